"""Kinect v2 through libfreenect2's Python binding ``pylibfreenect2``.

UNTESTED WITHOUT HARDWARE: the tests run this code against a fake of the binding's small
surface (``Freenect2``, ``SyncMultiFrameListener``, ``Registration``, ``Frame``,
``FrameType``, packet pipelines), written from the binding's documented API; the first run on a
real sensor should check the frame orientation and the colour order. Install notes
(libfreenect2 build, udev rules, the binding): ``devices/camera/KINECT2.md``.

Frames: libfreenect2's registration undistorts the 512 x 424 depth image and registers the
1920 x 1080 colour to it, so depth and colour are pixel-aligned and the intrinsics are the IR
camera's own ``fx fy cx cy`` without distortion (the sensor's factory calibration, the starting
calibration). IR is the raw (still distorted) amplitude image. The binding's
``waitForNewFrame`` cannot time out, so frames are polled with ``hasNewFrame`` and a deadline.
"""

from __future__ import annotations

import importlib
import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.camera.base import CameraInfo, CameraTimeout, CameraUnavailable, DepthCamera
from devices.camera.frames import Frame, Intrinsics

log = logging.getLogger(__name__)

WIDTH, HEIGHT = 512, 424
POLL_S = 0.002
PIPELINES = {
    "cpu": "CpuPacketPipeline",
    "opengl": "OpenGLPacketPipeline",
    "opencl": "OpenCLPacketPipeline",
    "cuda": "CudaPacketPipeline",
}
INSTALL_HINT = (
    "Kinect v2 needs libfreenect2 and its Python binding pylibfreenect2, which pip cannot "
    "build without the C library: see packaging/README.md (Kinect v2)"
)


def load_binding() -> Any:
    """The ``pylibfreenect2`` module, or :class:`CameraUnavailable` saying how to install it."""
    try:
        return importlib.import_module("pylibfreenect2")
    except ImportError as error:
        raise CameraUnavailable(f"{INSTALL_HINT} ({error})") from None


def _text(serial: Any) -> str:
    return serial.decode("ascii", "replace") if isinstance(serial, bytes) else str(serial)


class Kinect2Camera(DepthCamera):
    """A Kinect v2 (``serial``, default the first found) through ``pylibfreenect2``.

    ``pipeline``: ``cpu``, ``opengl``, ``opencl``, ``cuda`` or ``None`` (libfreenect2's
    default). ``binding``: the module to use instead of importing ``pylibfreenect2`` (tests).
    ``clock`` and ``sleep`` time the frame timeout (a fake pair in tests).
    """

    def __init__(
        self,
        serial: str | None = None,
        pipeline: str | None = None,
        binding: Any = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__()
        self._clock, self._sleep = clock, sleep
        if pipeline is not None and pipeline not in PIPELINES:
            raise ValueError(f"pipeline must be one of {', '.join(PIPELINES)}, got {pipeline!r}")
        self.serial = serial
        self.pipeline = pipeline
        self._binding = binding
        self._device: Any = None
        self._listener: Any = None
        self._registration: Any = None
        self._undistorted: Any = None
        self._registered: Any = None
        self._intrinsics: Intrinsics | None = None
        self.ir_distortion: tuple[float, ...] = ()
        """The raw IR image's distortion (k1, k2, p1, p2, k3) from the sensor."""

    @property
    def intrinsics(self) -> Intrinsics:
        if self._intrinsics is None:
            raise CameraUnavailable("Kinect v2 intrinsics are known once the camera is open")
        return self._intrinsics

    @property
    def info(self) -> CameraInfo:
        return CameraInfo("kinect2", "Kinect v2 (libfreenect2)", self.serial or "unknown")

    def _open(self) -> None:
        fl = self._binding if self._binding is not None else load_binding()
        freenect = fl.Freenect2()
        raw_serial = self._find(freenect)
        self.serial = _text(raw_serial)
        pipeline = getattr(fl, PIPELINES[self.pipeline])() if self.pipeline else None
        device = freenect.openDevice(raw_serial, pipeline=pipeline)
        if device is None:
            raise CameraUnavailable(f"Kinect v2 {self.serial} found but cannot be opened")
        types = fl.FrameType.Color | fl.FrameType.Ir | fl.FrameType.Depth
        listener = fl.SyncMultiFrameListener(types)
        device.setColorFrameListener(listener)
        device.setIrAndDepthFrameListener(listener)
        if device.start() is False:
            raise CameraUnavailable(f"Kinect v2 {self.serial} does not start streaming")
        ir_params = device.getIrCameraParams()
        self._registration = fl.Registration(ir_params, device.getColorCameraParams())
        self._undistorted = fl.Frame(WIDTH, HEIGHT, 4)
        self._registered = fl.Frame(WIDTH, HEIGHT, 4)
        self._device, self._listener = device, listener
        self._intrinsics = Intrinsics(
            WIDTH, HEIGHT, float(ir_params.fx), float(ir_params.fy),
            float(ir_params.cx), float(ir_params.cy),
        )  # fmt: skip
        self.ir_distortion = tuple(
            float(getattr(ir_params, k)) for k in ("k1", "k2", "p1", "p2", "k3")
        )
        log.info("Kinect v2 %s open: %s", self.serial, self._intrinsics)

    def _find(self, freenect: Any) -> Any:
        count = int(freenect.enumerateDevices())
        if count == 0:
            raise CameraUnavailable(
                "no Kinect v2 found: is it on a USB 3 port, powered by its adapter, and are "
                "the udev rules installed (packaging/README.md, Kinect v2)?"
            )
        serials = [freenect.getDeviceSerialNumber(i) for i in range(count)]
        if self.serial is None:
            return serials[0]
        for serial in serials:
            if _text(serial) == self.serial:
                return serial
        found = ", ".join(_text(s) for s in serials)
        raise CameraUnavailable(f"Kinect v2 {self.serial} not found (connected: {found})")

    def _close(self) -> None:
        device, self._device = self._device, None
        if device is not None:
            try:
                device.stop()
                device.close()
            except Exception:  # the device may already be gone; closing must not fail
                log.exception("closing Kinect v2 %s", self.serial)

    def _read(self, timeout_s: float) -> Frame:
        deadline = self._clock() + timeout_s
        while not self._listener.hasNewFrame():
            if self._clock() >= deadline:
                raise CameraTimeout(
                    f"no frame from Kinect v2 {self.serial} for {timeout_s:.1f} s "
                    "(unplugged, or not enough USB 3 bandwidth?)"
                )
            self._sleep(POLL_S)
        stamp = time.monotonic()  # frame ages are on the real clock (quality.py)
        frames = self._listener.waitForNewFrame()
        try:
            depth = frames["depth"]
            self._registration.apply(frames["color"], depth, self._undistorted, self._registered)
            depth_mm = np.array(self._undistorted.asarray(np.float32), np.float32)
            bgrx = np.array(self._registered.asarray(np.uint8), np.uint8)
            ir = np.array(frames["ir"].asarray(np.float32), np.float32)
            number, device_time = int(depth.sequence), int(depth.timestamp)
        finally:
            self._listener.release(frames)
        meta: dict[str, object] = {"frame_number": number, "device_timestamp": device_time}
        return Frame(_depth_m(depth_mm), _rgb(bgrx), _ir16(ir), stamp, meta)


def _depth_m(depth_mm: NDArray[np.float32]) -> NDArray[np.float32]:
    """libfreenect2 depth (mm, 0 = none) as metres with NaN where missing."""
    depth_m = depth_mm / np.float32(1000.0)
    depth_m[~(depth_mm > 0) | ~np.isfinite(depth_mm)] = np.nan
    return depth_m


def _rgb(bgrx: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Registered colour (H, W, 4) BGRX as (H, W, 3) RGB."""
    return np.ascontiguousarray(bgrx[:, :, 2::-1])


def _ir16(ir: NDArray[np.float32]) -> NDArray[np.uint16]:
    """IR amplitude (float32, 0-65535) as uint16."""
    return np.clip(np.nan_to_num(ir), 0, 65535).astype(np.uint16)
