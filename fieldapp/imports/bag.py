"""``fieldapp import bag``: a RealSense recording (``.bag``, recorded by the SDK) into a session,
read through the SDK's own playback, frame by frame.

With a colour stream, depth is aligned to colour (``rs.align``) and the camera is the colour
stream's, so depth and colour are registered pixel for pixel as the session format wants;
without one the captures are depth-only and the camera is the depth stream's. Every
``every``-th frame set becomes view ``k`` of station 1 at ``k * step_deg``.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.camera.base import CameraUnavailable
from devices.camera.realsense import load_binding
from fieldapp.errors import FieldappError
from fieldapp.imports.camera import IMPORT_STATION, import_calibration, turntable_fields
from fieldapp.imports.folder import ImportResult
from fieldapp.io.calibration import DepthCamera
from fieldapp.io.session import now_iso
from fieldapp.io.writer import SessionWriter

log = logging.getLogger(__name__)

WAIT_MS = 2000
"""How long one read of the playback may wait for the next frame set."""


@dataclass
class BagOptions:
    every: int = 1
    step_deg: float = 45.0
    axis_distance_m: float = 0.0
    max_views: int | None = None
    session_id: str | None = None


@dataclass
class BagFrame:
    """One frame set: depth (H, W) float32 m, NaN missing; colour (H, W, 3) uint8 or None."""

    depth_m: NDArray[np.float32]
    color: NDArray[np.uint8] | None


class _Playback:
    """The recording played sensor by sensor as fast as it can be decoded, colour-aligned when
    present.

    Not through ``rs.pipeline`` nor an ``rs.syncer``: a pipeline starts playing before real time
    can be turned off, and both hand frame sets on through a queue that drops the older one
    when the reader is slower (librealsense issues #1180, #2360), so on a loaded machine some
    were lost. Here the playback device is set to non-real time before any stream starts; each
    frame goes into a bounded queue whose full state holds the playback back, so every
    recorded frame comes out; depth and colour are paired here by timestamp (within half a
    frame period) and the pair made one frame set for ``rs.align``.
    """

    def __init__(self, rs: Any, path: Path) -> None:
        self.rs = rs
        try:
            device = rs.context().load_device(str(path))
        except RuntimeError as error:
            raise FieldappError(f"{path}: the RealSense SDK cannot play it ({error})") from None
        self.playback = device.as_playback()
        self.playback.set_real_time(False)
        wanted = (rs.stream.depth, rs.stream.color)
        streams: dict[Any, Any] = {}
        self.opened: list[Any] = []
        others: set[str] = set()
        for sensor in device.query_sensors():
            profiles = []
            for profile in sensor.get_stream_profiles():
                kind = profile.stream_type()
                if kind in wanted and kind not in streams and profile.is_video_stream_profile():
                    streams[kind] = profile
                    profiles.append(profile)
                elif kind not in wanted:
                    others.add(str(kind).split(".")[-1])
            if profiles:
                sensor.open(profiles)
                self.opened.append(sensor)
        if rs.stream.depth not in streams:
            self._close()
            raise FieldappError(f"{path}: the recording has no depth stream")
        self.has_color = rs.stream.color in streams
        camera_stream = streams[rs.stream.color if self.has_color else rs.stream.depth]
        self.intrinsics = camera_stream.as_video_stream_profile().get_intrinsics()
        self.align = rs.align(rs.stream.color) if self.has_color else None
        self.others = sorted(others)
        depth_fps = float(streams[rs.stream.depth].fps() or 30)
        self.pair_tolerance_ms = 500.0 / depth_fps
        self.queue: queue.Queue[Any] = queue.Queue(maxsize=8)
        self.stopping = threading.Event()
        self.pairs_dropped = 0
        """Depth or colour frames without a partner within the tolerance (not imported)."""
        self._pair: list[Any] = []
        self._composer = rs.processing_block(self._compose)
        self._composed = rs.frame_queue(2, keep_frames=True)
        self._composer.start(self._composed)
        self._last: dict[Any, tuple[int, float]] = {}
        self._start()

    def _start(self) -> None:
        """Start every sensor, then play.

        The playback starts reading the file as soon as its first sensor starts, and drops the
        frames of a sensor not yet started ("stream is no longer active"): started one by one,
        depth could be read alone for a while and its colour partners lost (a loaded CI machine
        lost six of eight). Paused first, it reads nothing for anyone until every sensor is
        started and it is resumed from the beginning of the file."""
        self.playback.pause()
        for sensor in self.opened:
            self._start_sensor(sensor)
        self.playback.resume()

    def _start_sensor(self, sensor: Any) -> None:
        sensor.start(self._take)

    def _take(self, frame: Any) -> None:
        """The SDK's callback: queue ``frame``, waiting while the reader is behind (in non-real
        time that holds the playback back) unless the import is stopping."""
        frame.keep()
        while not self.stopping.is_set():
            try:
                self.queue.put(frame, timeout=0.1)
                return
            except queue.Full:
                continue

    def _compose(self, _frame: Any, source: Any) -> None:
        source.frame_ready(source.allocate_composite_frame(self._pair))

    def frames(self) -> Iterator[BagFrame]:
        depths: deque[Any] = deque()
        colours: deque[Any] = deque()
        while True:
            try:
                frame = self.queue.get(timeout=WAIT_MS / 1000)
            except queue.Empty:
                if self.playback.current_status() == self.rs.playback_status.stopped:
                    self.pairs_dropped += len(depths) + len(colours) if self.has_color else 0
                    return
                continue
            kind = frame.get_profile().stream_type()
            if self._repeated(kind, frame):
                continue
            if not self.has_color:
                if kind == self.rs.stream.depth:
                    yield BagFrame(_depth_m(frame.as_depth_frame()), None)
                continue
            (depths if kind == self.rs.stream.depth else colours).append(frame)
            while depths and colours:
                depth, colour = depths[0], colours[0]
                dt_ms = depth.get_timestamp() - colour.get_timestamp()
                if abs(dt_ms) <= self.pair_tolerance_ms:
                    depths.popleft(), colours.popleft()
                    yield self._aligned(depth, colour)
                else:  # the older of the two has no partner: the other stream moved on
                    (depths if dt_ms < 0 else colours).popleft()
                    self.pairs_dropped += 1

    def _repeated(self, kind: Any, frame: Any) -> bool:
        """Whether ``frame`` is the last frame of its stream again (same number and time): the
        one frame read while paused can reach its sensor's callback after the resume, which
        reads it again. Only that exact repeat: a recording whose clock starts over keeps its
        later frames."""
        stamp = (frame.get_frame_number(), frame.get_timestamp())
        if self._last.get(kind) == stamp:
            return True
        self._last[kind] = stamp
        return False

    def _aligned(self, depth: Any, colour: Any) -> BagFrame:
        assert self.align is not None
        self._pair = [depth, colour]
        self._composer.invoke(depth)
        ok, composite = self._composed.try_wait_for_frame(WAIT_MS)
        if not ok:
            raise FieldappError("the RealSense SDK did not pair a depth and a colour frame")
        frames = self.align.process(composite.as_frameset())
        return BagFrame(_depth_m(frames.get_depth_frame()), _rgb(self.rs, frames.get_color_frame()))

    def stop(self) -> None:
        self.stopping.set()  # a callback waiting for room gives up
        for sensor in self.opened:
            try:
                sensor.stop()
            except RuntimeError:
                log.exception("stopping the RealSense playback")
        self._close()

    def _close(self) -> None:
        for sensor in self.opened:
            try:
                sensor.close()
            except RuntimeError:
                log.exception("closing the RealSense playback")
        self.opened = []


def _depth_m(depth: Any) -> NDArray[np.float32]:
    units = np.asarray(depth.get_data(), np.uint16)
    depth_m: NDArray[np.float32] = units.astype(np.float32) * np.float32(depth.get_units())
    depth_m[units == 0] = np.nan
    return depth_m


def _rgb(rs: Any, color: Any) -> NDArray[np.uint8] | None:
    fmt = color.get_profile().format()
    pixels = np.array(np.asanyarray(color.get_data()), np.uint8)
    if fmt == rs.format.rgb8:
        return pixels
    if fmt == rs.format.bgr8:
        return np.ascontiguousarray(pixels[:, :, ::-1])
    return None


def bag_camera(intrinsics: Any) -> DepthCamera:
    """The session's depth camera from the SDK's intrinsics (Brown-Conrady coefficients)."""
    coeffs = [float(c) for c in intrinsics.coeffs][:5]
    return DepthCamera(
        width=int(intrinsics.width),
        height=int(intrinsics.height),
        fx=float(intrinsics.fx),
        fy=float(intrinsics.fy),
        cx=float(intrinsics.ppx),
        cy=float(intrinsics.ppy),
        distortion=(coeffs + [0.0] * 5)[:5],
        depth_scale=1000.0,
    )


def import_bag(path: Path, out: Path, options: BagOptions) -> ImportResult:
    """Write a session in ``out`` from the RealSense recording ``path``."""
    if not path.is_file():
        raise FieldappError(f"{path}: no such recording")
    if options.every < 1:
        raise FieldappError(f"--every {options.every}: must be at least 1")
    try:
        rs = load_binding()
    except CameraUnavailable as error:
        raise FieldappError(str(error)) from None
    playback = _Playback(rs, path)
    lines = [f"{path}: stream {name} not used" for name in playback.others]
    if not playback.has_color:
        lines.append(f"{path}: no colour stream: the captures are depth-only")
    try:
        return _write(playback, path, out, options, lines)
    finally:
        playback.stop()


def _write(
    playback: _Playback, path: Path, out: Path, options: BagOptions, lines: list[str]
) -> ImportResult:
    calibration = import_calibration(
        bag_camera(playback.intrinsics), options.step_deg, options.axis_distance_m, None
    )
    provenance: dict[str, Any] = {
        "imported": {"from": str(path.resolve()), "at": now_iso(), "by": "bag"}
    }
    provenance |= turntable_fields(options.axis_distance_m)
    writer = SessionWriter.create(out, options.session_id or path.stem, calibration, provenance)
    result = ImportResult(out, 0, 0, lines)
    for index, frame in enumerate(playback.frames()):
        if index % options.every:
            continue
        if options.max_views is not None and result.captures >= options.max_views:
            break
        view = result.captures
        writer.add_capture(
            IMPORT_STATION, view, frame.depth_m, frame.color, angle_deg=view * options.step_deg
        )
        result.captures += 1
        result.depth_only += frame.color is None
    if playback.pairs_dropped:
        lines.append(
            f"{path}: {playback.pairs_dropped} depth or colour frames had no partner within "
            f"{playback.pair_tolerance_ms:.1f} ms and were not imported"
        )
    if playback.has_color and result.depth_only:
        lines.append(
            f"{path}: colour frames not used (not RGB8 or BGR8): {result.depth_only} captures "
            "are depth-only"
        )
    if result.captures == 0:
        raise FieldappError(f"{path}: the recording holds no depth frame")
    return result
