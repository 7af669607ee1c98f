"""Intel RealSense D4xx through ``pyrealsense2`` (optional extra ``realsense``).

Depth and colour stream at a configured resolution and rate; every frame set's depth is
aligned to the colour camera (``rs.align``), so depth and colour are pixel-aligned and the
intrinsics are the colour stream's. ``recording`` plays a file recorded by the SDK
(``rs.recorder``) through the SDK's own playback, frame by frame (not in real time), with the
same code path as a live camera: that is how the tests run without hardware.
"""

from __future__ import annotations

import importlib
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from devices.camera.base import (
    CameraDisconnected,
    CameraEnded,
    CameraInfo,
    CameraTimeout,
    CameraUnavailable,
    DepthCamera,
)
from devices.camera.frames import Frame, Intrinsics

log = logging.getLogger(__name__)


def load_binding() -> Any:
    """The ``pyrealsense2`` module, or :class:`CameraUnavailable` saying how to install it."""
    try:
        return importlib.import_module("pyrealsense2")
    except ImportError as error:
        raise CameraUnavailable(
            f"RealSense needs pyrealsense2: pip install 'fieldapp[realsense]' ({error})"
        ) from None


class RealSenseCamera(DepthCamera):
    """A RealSense camera (``serial``, default the first found) or an SDK ``recording``."""

    def __init__(
        self,
        serial: str | None = None,
        width: int = 640,
        height: int = 480,
        fps: int = 30,
        recording: Path | None = None,
    ) -> None:
        super().__init__()
        self.serial = serial
        self.width, self.height, self.fps = width, height, fps
        self.recording = recording
        self._rs: Any = None
        self._pipeline: Any = None
        self._align: Any = None
        self._playback: Any = None
        self._intrinsics: Intrinsics | None = None
        self._model = "RealSense"

    @property
    def intrinsics(self) -> Intrinsics:
        if self._intrinsics is None:
            raise CameraUnavailable("RealSense intrinsics are known once the camera is open")
        return self._intrinsics

    @property
    def info(self) -> CameraInfo:
        return CameraInfo("realsense", self._model, self.serial or "unknown")

    def _open(self) -> None:
        rs = self._rs = load_binding()
        config = self._config(rs)
        pipeline = rs.pipeline()
        try:
            profile = pipeline.start(config)
        except RuntimeError as error:
            raise CameraUnavailable(f"RealSense cannot start: {error}") from None
        device = profile.get_device()
        if self.recording is not None:
            self._playback = device.as_playback()
            self._playback.set_real_time(False)
        self.serial = str(device.get_info(rs.camera_info.serial_number))
        self._model = str(device.get_info(rs.camera_info.name))
        color = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
        self._intrinsics = Intrinsics(
            int(color.width), int(color.height), float(color.fx), float(color.fy),
            float(color.ppx), float(color.ppy), tuple(float(c) for c in color.coeffs),
        )  # fmt: skip
        self._align = rs.align(rs.stream.color)
        self._pipeline = pipeline
        log.info("%s %s open: %s", self._model, self.serial, self._intrinsics)

    def _config(self, rs: Any) -> Any:
        config = rs.config()
        if self.recording is not None:
            if not Path(self.recording).is_file():
                raise CameraUnavailable(f"{self.recording}: no such RealSense recording")
            config.enable_device_from_file(str(self.recording), repeat_playback=False)
            return config
        serials = [d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()]
        if not serials:
            raise CameraUnavailable("no RealSense camera found (USB 3 cable and port?)")
        if self.serial is not None:
            if self.serial not in serials:
                raise CameraUnavailable(
                    f"RealSense {self.serial} not found (connected: {', '.join(serials)})"
                )
            config.enable_device(self.serial)
        size = (self.width, self.height)
        config.enable_stream(rs.stream.depth, *size, rs.format.z16, self.fps)
        config.enable_stream(rs.stream.color, *size, rs.format.rgb8, self.fps)
        return config

    def _close(self) -> None:
        pipeline, self._pipeline = self._pipeline, None
        if pipeline is not None:
            try:
                pipeline.stop()
            except RuntimeError:
                log.exception("stopping RealSense %s", self.serial)

    def _read(self, timeout_s: float) -> Frame:
        rs = self._rs
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            ok, frames = self._pipeline.try_wait_for_frames(max(1, int(remaining * 1000)))
            if not ok:
                break
            stamp = time.monotonic()
            aligned = self._align.process(frames)
            depth, color = aligned.get_depth_frame(), aligned.get_color_frame()
            if depth and color:
                return self._frame(rs, depth, color, stamp)
        raise self._no_frame(rs, timeout_s)

    def _frame(self, rs: Any, depth: Any, color: Any, stamp: float) -> Frame:
        units = np.asanyarray(depth.get_data())
        depth_m = units.astype(np.float32) * np.float32(depth.get_units())
        depth_m[units == 0] = np.nan
        rgb = np.array(np.asanyarray(color.get_data()), np.uint8)
        if color.get_profile().format() == rs.format.bgr8:
            rgb = np.ascontiguousarray(rgb[:, :, ::-1])
        meta: dict[str, object] = {
            "frame_number": int(depth.get_frame_number()),
            "device_timestamp_ms": float(depth.get_timestamp()),
        }
        return Frame(depth_m, rgb, None, stamp, meta)

    def _no_frame(self, rs: Any, timeout_s: float) -> Exception:
        """Why no frame came: the recording ended, the device is gone, or a timeout."""
        if self._playback is not None:
            if self._playback.current_status() == rs.playback_status.stopped:
                return CameraEnded(f"RealSense recording {self.recording} has played to its end")
            return CameraTimeout(f"no frame from {self.recording} for {timeout_s:.1f} s")
        present = [d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()]
        if self.serial not in present:
            return CameraDisconnected(f"RealSense {self.serial} was disconnected")
        return CameraTimeout(f"no frame from RealSense {self.serial} for {timeout_s:.1f} s")
