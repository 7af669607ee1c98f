"""RealSense backend through the SDK's own playback of a recording made with the SDK's
software device: the real pipeline, alignment and frame code run without hardware."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from devices.camera.base import CameraEnded, CameraUnavailable
from devices.camera.realsense import RealSenseCamera

rs = pytest.importorskip("pyrealsense2")

DEPTH_W, DEPTH_H, DEPTH_F = 64, 48, 50.0
COLOR_W, COLOR_H, COLOR_F = 80, 60, 60.0
FRAMES = 10


def _intrinsics(width: int, height: int, f: float) -> Any:
    intrinsics = rs.intrinsics()
    intrinsics.width, intrinsics.height = width, height
    intrinsics.fx = intrinsics.fy = f
    intrinsics.ppx, intrinsics.ppy = width / 2, height / 2
    intrinsics.model = rs.distortion.brown_conrady
    intrinsics.coeffs = [0.0] * 5
    return intrinsics


def _stream(kind: Any, uid: int, size: tuple[int, int, float], fmt: Any, bpp: int) -> Any:
    stream = rs.video_stream()
    stream.type, stream.index, stream.uid = kind, 0, uid
    stream.width, stream.height, stream.fps, stream.bpp, stream.fmt = size[0], size[1], 30, bpp, fmt
    stream.intrinsics = _intrinsics(*size)
    return stream


def depth_mm(index: int) -> tuple[int, int]:
    """(left half, right half) depth of frame ``index`` in millimetres."""
    return 1000 + 10 * index, 2000 + 10 * index


def _push(sensor: Any, profile: Any, pixels: np.ndarray, bpp: int, index: int) -> None:
    frame = rs.software_video_frame()
    frame.pixels, frame.bpp, frame.stride = pixels, bpp, pixels.shape[1] * bpp
    frame.timestamp, frame.frame_number = index * 33.3, index
    frame.domain = rs.timestamp_domain.hardware_clock
    frame.profile = profile.as_video_stream_profile()
    if bpp == 2:
        frame.depth_units = 0.001
    sensor.on_video_frame(frame)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recording of a software D4xx: depth 64 x 48 (f 50 px) split into a near left half
    and a far right half, colour 80 x 60 (f 60 px) whose grey level is the frame index x 10,
    the two cameras at the same place (identity extrinsics)."""
    path = tmp_path_factory.mktemp("rs") / "recording.db3"
    device = rs.software_device()
    depth_sensor, color_sensor = device.add_sensor("Depth"), device.add_sensor("Color")
    depth_profile = depth_sensor.add_video_stream(
        _stream(rs.stream.depth, 0, (DEPTH_W, DEPTH_H, DEPTH_F), rs.format.z16, 2)
    )
    color_profile = color_sensor.add_video_stream(
        _stream(rs.stream.color, 1, (COLOR_W, COLOR_H, COLOR_F), rs.format.rgb8, 3)
    )
    depth_sensor.add_read_only_option(rs.option.depth_units, 0.001)
    device.register_info(rs.camera_info.serial_number, "SW-0042")
    device.register_info(rs.camera_info.name, "Software D435")
    extrinsics = rs.extrinsics()
    extrinsics.rotation, extrinsics.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
    depth_profile.register_extrinsics_to(color_profile, extrinsics)
    recorder = rs.recorder(str(path), device)
    queue = rs.frame_queue(100)
    for sensor, profile in ((depth_sensor, depth_profile), (color_sensor, color_profile)):
        sensor.open(profile)
        sensor.start(queue)
    for index in range(FRAMES):
        depth = np.empty((DEPTH_H, DEPTH_W), np.uint16)
        depth[:, : DEPTH_W // 2], depth[:, DEPTH_W // 2 :] = depth_mm(index)
        _push(depth_sensor, depth_profile, depth, 2, index)
        _push(
            color_sensor,
            color_profile,
            np.full((COLOR_H, COLOR_W, 3), 10 * index, np.uint8),
            3,
            index,
        )
        time.sleep(0.01)
    for sensor in (depth_sensor, color_sensor):
        sensor.stop()
        sensor.close()
    del recorder  # closes the file
    return path


def test_playback_gives_depth_aligned_to_colour(recording: Path) -> None:
    camera = RealSenseCamera(recording=recording)
    frames = []
    with camera:
        assert camera.info.serial == "SW-0042" and camera.info.model == "Software D435"
        intrinsics = camera.intrinsics
        assert (intrinsics.width, intrinsics.height) == (COLOR_W, COLOR_H)
        assert intrinsics.fx == pytest.approx(COLOR_F) and intrinsics.cx == pytest.approx(40)
        for _ in range(FRAMES + 2):
            try:
                frames.append(camera.read_frame(timeout_s=1.0))
            except CameraEnded as ended:
                assert "played to its end" in str(ended)
                break
        else:
            pytest.fail("the recording did not end")
    assert len(frames) >= FRAMES - 2  # the SDK's syncer may drop the first set
    for frame in frames:
        index = int(frame.color[0, 0, 0]) // 10
        assert frame.depth_m.shape == (COLOR_H, COLOR_W) and frame.color.shape == (60, 80, 3)
        near_m, far_m = (mm / 1000 for mm in depth_mm(index))
        # depth column 32 (x = 0) lands on colour column 40; x = +-0.5 on 10 and 70
        left, right = frame.depth_m[5:55, 12:36], frame.depth_m[5:55, 44:68]
        assert np.isfinite(left).mean() > 0.95 and np.isfinite(right).mean() > 0.95
        assert np.nanmax(np.abs(left - near_m)) < 1e-3
        assert np.nanmax(np.abs(right - far_m)) < 1e-3
    numbers = [f.meta["frame_number"] for f in frames]
    assert numbers == sorted(numbers)


def test_missing_recording_library_and_device_are_clear(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with pytest.raises(CameraUnavailable, match=r"absent\.db3: no such RealSense recording"):
        RealSenseCamera(recording=tmp_path / "absent.db3").open()
    if len(rs.context().query_devices()) == 0:
        with pytest.raises(CameraUnavailable, match="no RealSense camera found"):
            RealSenseCamera().open()
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)
    with pytest.raises(CameraUnavailable, match=r"pip install 'fieldapp\[realsense\]'"):
        RealSenseCamera().open()
