"""Replay of a recorded session folder (``shared/spec/session-format.md``) as a camera.

Plays the captures in session order or in a chosen order of (station, view) keys, once or
looping, as fast as asked or at the Kinect's 30 fps; :meth:`ReplayCamera.frame_at` reads one
capture directly. Frames are exactly what the files hold: depth = stored units /
``depth_scale`` as float32 (NaN where 0), colour as RGB, IR when recorded. ``devices`` cannot
use the core's readers, so this module reads ``session.json``, the calibration's
``depth_camera`` and the images itself, with only the checks replay needs.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from devices.camera.base import CameraEnded, CameraFormatError, CameraInfo, DepthCamera
from devices.camera.frames import Frame, Intrinsics

log = logging.getLogger(__name__)

Key = tuple[int, int] | tuple[int, int, str | None]
"""(station, view) or (station, view, target)."""


@dataclass(frozen=True)
class ReplayCapture:
    """One capture entry of ``session.json``: paths relative to the folder, and its fields."""

    index: int
    station: int
    view: int
    target: str | None
    depth: str
    color: str
    ir: str | None
    fields: dict[str, Any]


def read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CameraFormatError(f"{path}: file is missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CameraFormatError(f"{path}: not readable JSON ({error})") from None


def _field(data: Any, name: str, kind: type | tuple[type, ...], where: str) -> Any:
    value = data.get(name) if isinstance(data, dict) else None
    if not isinstance(value, kind) or isinstance(value, bool):
        raise CameraFormatError(f"{where}: {name}: missing or not a {_kind_name(kind)}")
    return value


def _kind_name(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {int: "integer", float: "number", str: "string"}
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def _relative(value: str | None, where: str, name: str) -> str | None:
    """A path inside the session folder (forward slashes), or a :class:`CameraFormatError`."""
    if value is None:
        return None
    path = value.replace("\\", "/")
    parts = path.split("/")
    if path.startswith("/") or ".." in parts or ":" in parts[0]:
        raise CameraFormatError(f"{where}: {name}: {value!r} is not inside the session folder")
    return path


def parse_captures(document: Any, session_file: Path) -> list[ReplayCapture]:
    """The captures of a session document, checked for what replay needs."""
    entries = _field(document, "captures", list, str(session_file))
    captures = []
    for index, entry in enumerate(entries):
        where = f"{session_file}: captures[{index}]"
        station = _field(entry, "station", int, where)
        view = _field(entry, "view", int, where)
        target = entry.get("target")
        ir = entry.get("ir")
        captures.append(
            ReplayCapture(
                index=index,
                station=station,
                view=view,
                target=target if isinstance(target, str) else None,
                depth=str(_relative(_field(entry, "depth", str, where), where, "depth")),
                color=str(_relative(_field(entry, "color", str, where), where, "color")),
                ir=_relative(ir if isinstance(ir, str) else None, where, "ir"),
                fields=dict(entry),
            )
        )
    return captures


def parse_depth_camera(calibration: Any, path: Path) -> tuple[Intrinsics, float]:
    """(intrinsics, depth_scale) from a calibration document's ``depth_camera``."""
    camera = _field(calibration, "depth_camera", dict, str(path))
    where = f"{path}: depth_camera"
    numbers = {k: float(_field(camera, k, (int, float), where)) for k in ("fx", "fy", "cx", "cy")}
    distortion = camera.get("distortion", [0.0] * 5)
    if not isinstance(distortion, list) or not all(isinstance(c, (int, float)) for c in distortion):
        raise CameraFormatError(f"{where}: distortion: not a list of numbers")
    scale = float(_field(camera, "depth_scale", (int, float), where))
    if scale <= 0:
        raise CameraFormatError(f"{where}: depth_scale: must be positive, got {scale}")
    intrinsics = Intrinsics(
        width=_field(camera, "width", int, where),
        height=_field(camera, "height", int, where),
        distortion=tuple(float(c) for c in distortion),
        **numbers,
    )
    return intrinsics, scale


def _decode(path: Path, field: str) -> NDArray[Any]:
    try:
        data = path.read_bytes()
    except OSError as error:
        raise CameraFormatError(f"{path}: {field}: cannot read ({error.strerror})") from None
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if image is None:
        raise CameraFormatError(f"{path}: {field}: not a decodable image")
    return np.asarray(image)


def read_depth_m(path: Path, depth_scale: float) -> NDArray[np.float32]:
    """A 16-bit depth PNG as (H, W) float32 metres, NaN where 0."""
    units = _decode(path, "depth")
    if units.ndim != 2 or units.dtype != np.uint16:
        raise CameraFormatError(f"{path}: depth: must be a single-channel 16-bit image")
    depth_m = units.astype(np.float32) / np.float32(depth_scale)
    depth_m[units == 0] = np.nan
    return depth_m


def read_rgb(path: Path) -> NDArray[np.uint8]:
    """A colour image (PNG or JPEG) as (H, W, 3) uint8 RGB."""
    image = _decode(path, "color")
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise CameraFormatError(f"{path}: color: must be an 8-bit RGB image")
    code = cv2.COLOR_BGR2RGB if image.shape[2] == 3 else cv2.COLOR_BGRA2RGB
    return np.ascontiguousarray(cv2.cvtColor(image, code))


def read_ir(path: Path) -> NDArray[np.uint16]:
    image = _decode(path, "ir")
    if image.ndim != 2 or image.dtype != np.uint16:
        raise CameraFormatError(f"{path}: ir: must be a single-channel 16-bit image")
    return image


class ReplayCamera(DepthCamera):
    """Plays the session folder ``folder`` (see the module's docstring).

    ``keys``: the (station, view[, target]) captures to play, in that order (default: all, in
    session order; a two-element key means the capture without a target). ``loop``: start
    again after the last one (otherwise :class:`CameraEnded`). ``fps``: pace frames in real
    time; ``None`` delivers them as fast as they are read.
    """

    def __init__(
        self,
        folder: Path,
        keys: Sequence[Key] | None = None,
        loop: bool = False,
        fps: float | None = None,
    ) -> None:
        super().__init__()
        self.folder = Path(folder)
        self.loop = loop
        self.period_s = 1.0 / fps if fps else 0.0
        session_file = self.folder / "session.json"
        if not self.folder.is_dir():
            raise CameraFormatError(f"{self.folder}: not a session folder (no such folder)")
        document = read_json(session_file)
        self.session_id = str(document.get("id", self.folder.name))
        self.captures = parse_captures(document, session_file)
        calibration_path = self.folder / _field(document, "calibration", str, str(session_file))
        self._intrinsics, self.depth_scale = parse_depth_camera(
            read_json(calibration_path), calibration_path
        )
        self.playlist = [self.find(k) for k in keys] if keys is not None else list(self.captures)
        if not self.playlist:
            raise CameraFormatError(f"{session_file}: captures: nothing to play")
        self._position = 0
        self._frame_number = 0
        self._next_s = 0.0

    @property
    def intrinsics(self) -> Intrinsics:
        return self._intrinsics

    @property
    def info(self) -> CameraInfo:
        return CameraInfo("replay", "recorded session", f"replay:{self.session_id}", True)

    def find(self, key: Key) -> ReplayCapture:
        """The capture of (station, view[, target]); :class:`CameraFormatError` when absent."""
        station, view = key[0], key[1]
        target = key[2] if len(key) > 2 else None
        for capture in self.captures:
            if (capture.station, capture.view, capture.target) == (station, view, target):
                return capture
        what = f"station {station} view {view}" + (f" target {target}" if target else "")
        raise CameraFormatError(f"{self.folder / 'session.json'}: no capture of {what}")

    def frame_at(self, station: int, view: int, target: str | None = None) -> Frame:
        """The frame of one capture, read now (works whether the camera is open or not)."""
        return self.load(self.find((station, view, target)))

    def load(self, capture: ReplayCapture) -> Frame:
        """Decode one capture's images into a frame (``meta`` holds its session fields)."""
        depth = read_depth_m(self.folder / capture.depth, self.depth_scale)
        color = read_rgb(self.folder / capture.color)
        ir = read_ir(self.folder / capture.ir) if capture.ir else None
        expected = (self._intrinsics.height, self._intrinsics.width)
        for name, shape in (("depth", depth.shape), ("color", color.shape[:2])):
            if tuple(shape) != expected:
                raise CameraFormatError(
                    f"{self.folder / getattr(capture, name)}: {name}: size {shape[1]} x "
                    f"{shape[0]} differs from the calibration's {expected[1]} x {expected[0]}"
                )
        meta: dict[str, object] = {**capture.fields, "capture_index": capture.index}
        return Frame(depth, color, ir, time.monotonic(), meta)

    def _open(self) -> None:
        self._position = 0
        self._next_s = time.monotonic()

    def _close(self) -> None:
        pass

    def _read(self, timeout_s: float) -> Frame:
        if self._position >= len(self.playlist):
            if not self.loop:
                raise CameraEnded(f"replay of {self.folder} has played all its captures")
            self._position = 0
        if self.period_s:
            delay = self._next_s - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            self._next_s = max(self._next_s + self.period_s, time.monotonic() - self.period_s)
        frame = self.load(self.playlist[self._position])
        frame.meta["frame_number"] = self._frame_number
        self._position += 1
        self._frame_number += 1
        return frame
