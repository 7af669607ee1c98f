"""Kinect v2 backend against a fake of pylibfreenect2's small surface (no hardware here).

The fake follows the binding's documented API: ``Freenect2`` (enumerateDevices,
getDeviceSerialNumber -> bytes, openDevice), ``Freenect2Device`` (listeners, start, stop,
close, camera parameters), ``SyncMultiFrameListener`` (hasNewFrame, waitForNewFrame -> a map
keyed "color"/"ir"/"depth", release), ``Registration.apply`` writing 512 x 424 undistorted
depth (float32 mm) and registered colour (BGRX uint8), ``Frame(w, h, bpp)``, ``FrameType``.
"""

from __future__ import annotations

import sys
from enum import IntEnum
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from devices.camera.base import CameraTimeout, CameraUnavailable
from devices.camera.kinect2 import POLL_S, Kinect2Camera

from ..fake_clock import FakeClock

H, W = 424, 512


class FrameType(IntEnum):
    Color = 1
    Ir = 2
    Depth = 4


class FakeFrame:
    def __init__(self, width: int, height: int, bytes_per_pixel: int, data: Any = None) -> None:
        self.width, self.height = width, height
        self.data = data if data is not None else np.zeros((height, width, 4), np.uint8)
        self.sequence, self.timestamp = 0, 0

    def asarray(self, dtype: Any = None) -> Any:
        if dtype == np.float32:
            return self.data.view(np.float32).reshape(self.height, self.width)
        return self.data


def scene(sequence: int) -> tuple[np.ndarray, np.ndarray]:
    """What the fake sensor sees: depth (mm, 0 = none) and colour (BGRX) of frame n."""
    depth = np.full((H, W), 1500.0 + sequence, np.float32)
    depth[:10] = 0.0
    bgrx = np.zeros((H, W, 4), np.uint8)
    bgrx[..., 0], bgrx[..., 1], bgrx[..., 2] = 10, 20, 30  # blue, green, red
    return depth, bgrx


class FakeListener:
    def __init__(self, types: int) -> None:
        assert types == FrameType.Color | FrameType.Ir | FrameType.Depth
        self.device: FakeDevice | None = None
        self.released = 0
        self.outstanding = 0

    def hasNewFrame(self) -> bool:
        return self.device is not None and self.device.streaming and self.device.frames_left > 0

    def waitForNewFrame(self) -> dict[str, FakeFrame]:
        assert self.device is not None and self.hasNewFrame()  # the real one would block
        self.device.frames_left -= 1
        self.device.sequence += 1
        depth_mm, _ = scene(self.device.sequence)
        depth = FakeFrame(W, H, 4, depth_mm.view(np.uint8).reshape(H, W, 4))
        depth.sequence, depth.timestamp = self.device.sequence, 1000 + self.device.sequence
        ir = FakeFrame(W, H, 4, np.full((H, W), 70000.0, np.float32).view(np.uint8))
        self.outstanding += 1
        return {"color": FakeFrame(1920, 1080, 4), "depth": depth, "ir": ir}

    def release(self, frames: dict[str, FakeFrame]) -> None:
        self.outstanding -= 1
        self.released += 1


class FakeRegistration:
    def __init__(self, ir_params: Any, color_params: Any) -> None:
        self.ir_params = ir_params

    def apply(
        self, color: FakeFrame, depth: FakeFrame, undistorted: FakeFrame, registered: FakeFrame
    ) -> None:
        assert (color.width, color.height, depth.width, depth.height) == (1920, 1080, W, H)
        depth_mm, bgrx = scene(depth.sequence)
        undistorted.data[...] = depth_mm.view(np.uint8).reshape(H, W, 4)
        registered.data[...] = bgrx


class FakeDevice:
    def __init__(self, serial: bytes, frames: int) -> None:
        self.serial, self.frames_left, self.sequence = serial, frames, 0
        self.streaming = self.closed = False

    def setColorFrameListener(self, listener: FakeListener) -> None:
        listener.device = self

    def setIrAndDepthFrameListener(self, listener: FakeListener) -> None:
        listener.device = self

    def start(self) -> None:
        self.streaming = True

    def stop(self) -> None:
        self.streaming = False

    def close(self) -> None:
        self.closed = True

    def getIrCameraParams(self) -> SimpleNamespace:
        return SimpleNamespace(
            fx=366.95, fy=364.79, cx=242.99, cy=207.70, k1=0.0966, k2=-0.283, k3=0.105, p1=0, p2=0
        )

    def getColorCameraParams(self) -> SimpleNamespace:
        return SimpleNamespace(fx=1081.37, fy=1081.37, cx=959.5, cy=539.5)


def fake_binding(serials: list[bytes], frames: int = 10) -> SimpleNamespace:
    devices = {s: FakeDevice(s, frames) for s in serials}

    class Freenect2:
        def enumerateDevices(self) -> int:
            return len(serials)

        def getDeviceSerialNumber(self, index: int) -> bytes:
            return serials[index]

        def openDevice(self, serial: bytes, pipeline: Any = None) -> FakeDevice:
            assert isinstance(serial, bytes)
            return devices[serial]

    return SimpleNamespace(
        Freenect2=Freenect2,
        SyncMultiFrameListener=FakeListener,
        Registration=FakeRegistration,
        Frame=FakeFrame,
        FrameType=FrameType,
        CpuPacketPipeline=lambda: "cpu",
        devices=devices,
    )


def test_frames_are_registered_depth_in_metres_and_rgb() -> None:
    binding = fake_binding([b"011054343347"])
    camera = Kinect2Camera(binding=binding)
    with camera:
        assert camera.info.serial == "011054343347"
        assert camera.intrinsics.fx == pytest.approx(366.95)
        assert camera.intrinsics.cy == pytest.approx(207.70)
        assert not camera.intrinsics.has_distortion  # the depth is undistorted
        assert camera.ir_distortion == pytest.approx((0.0966, -0.283, 0, 0, 0.105))
        frames = [camera.read_frame() for _ in range(3)]
        listener = camera._listener
    frame = frames[-1]
    assert frame.depth_m.shape == (H, W) and frame.depth_m.dtype == np.float32
    assert np.isnan(frame.depth_m[:10]).all()
    assert frame.depth_m[200, 100] == pytest.approx(1.503)
    assert frame.color.shape == (H, W, 3) and tuple(frame.color[5, 5]) == (30, 20, 10)
    assert frame.ir is not None and frame.ir.dtype == np.uint16 and frame.ir.max() == 65535
    assert [f.meta["frame_number"] for f in frames] == [1, 2, 3]
    assert listener.released == 3 and listener.outstanding == 0
    assert binding.devices[b"011054343347"].closed


def test_choosing_a_serial_and_a_pipeline() -> None:
    binding = fake_binding([b"A1", b"B2"])
    with Kinect2Camera("B2", pipeline="cpu", binding=binding) as camera:
        camera.read_frame()
    assert binding.devices[b"B2"].closed and not binding.devices[b"A1"].closed
    with pytest.raises(CameraUnavailable, match=r"Kinect v2 C3 not found \(connected: A1, B2\)"):
        Kinect2Camera("C3", binding=binding).open()
    with pytest.raises(ValueError, match="pipeline"):
        Kinect2Camera(pipeline="vulkan")


def test_no_device_and_no_binding_are_clear(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(CameraUnavailable, match=r"no Kinect v2 found.*udev"):
        Kinect2Camera(binding=fake_binding([])).open()
    monkeypatch.setitem(sys.modules, "pylibfreenect2", None)  # import fails
    with pytest.raises(CameraUnavailable, match=r"libfreenect2.*packaging/README\.md"):
        Kinect2Camera().open()


def test_no_frames_for_the_timeout_is_a_typed_error_not_a_hang() -> None:
    clock = FakeClock()
    camera = Kinect2Camera(binding=fake_binding([b"X"], frames=1), clock=clock, sleep=clock.sleep)
    with camera:
        camera.read_frame()
        started_s = clock()
        with pytest.raises(CameraTimeout, match=r"no frame from Kinect v2 X for 0\.3 s"):
            camera.read_frame(timeout_s=0.3)
        assert 0.3 <= clock() - started_s <= 0.3 + POLL_S + 1e-9
