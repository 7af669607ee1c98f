"""``fieldapp import bag``: RealSense recordings made with the SDK's software device, played
back through the SDK, into sessions that ``verify`` accepts."""

from __future__ import annotations

import queue
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fieldapp.cli import main
from fieldapp.errors import FieldappError
from fieldapp.imports.bag import BagOptions, import_bag
from fieldapp.io.session import load_session
from fieldapp.verify import verify_session

rs = pytest.importorskip("pyrealsense2")

W, H, F = 64, 48, 50.0
FRAMES = 8
SDK_WAIT_MS = 10_000  # a hang guard for the SDK's own waits, not a speed check


def _stream(kind: Any, uid: int, fmt: Any, bpp: int) -> Any:
    intrinsics = rs.intrinsics()
    intrinsics.width, intrinsics.height = W, H
    intrinsics.fx = intrinsics.fy = F
    intrinsics.ppx, intrinsics.ppy = W / 2, H / 2
    intrinsics.model = rs.distortion.brown_conrady
    intrinsics.coeffs = [0.0] * 5
    stream = rs.video_stream()
    stream.type, stream.index, stream.uid = kind, 0, uid
    stream.width, stream.height, stream.fps, stream.bpp, stream.fmt = W, H, 30, bpp, fmt
    stream.intrinsics = intrinsics
    return stream


def _push(sensor: Any, profile: Any, pixels: np.ndarray, bpp: int, index: int) -> None:
    frame = rs.software_video_frame()
    frame.pixels, frame.bpp, frame.stride = pixels, bpp, pixels.shape[1] * bpp
    frame.timestamp, frame.frame_number = index * 33.3, index
    frame.domain = rs.timestamp_domain.hardware_clock
    frame.profile = profile.as_video_stream_profile()
    if bpp == 2:
        frame.depth_units = 0.001
    sensor.on_video_frame(frame)


def record(path: Path, with_color: bool, attempts: int = 3) -> Path:
    """A software D4xx recording: depth of frame i is 1000 + 10 i mm everywhere; colour (same
    camera, same size) has grey level 10 i. Checked to hold every frame. The SDK's recorder
    writes on a thread of its own and gives up waiting for it after a timeout when its device
    closes, so on a saturated machine a recording can come out short: that fixture problem
    (not the importer's) is met by recording again, never by accepting a short file."""
    expected = {rs.stream.depth: FRAMES}
    if with_color:
        expected[rs.stream.color] = FRAMES
    recorded: dict[Any, int] = {}
    for attempt in range(attempts):
        target = path.with_name(f"{path.stem}-{attempt}{path.suffix}")
        _record_once(target, with_color)
        recorded = frames_in(target, sum(expected.values()))
        if recorded == expected:
            return target
    raise AssertionError(f"{path}: {attempts} recordings all short: {recorded}")


def _record_once(path: Path, with_color: bool) -> None:
    device = rs.software_device()
    sensors = [(device.add_sensor("Depth"), rs.stream.depth, rs.format.z16, 2)]
    if with_color:
        sensors.append((device.add_sensor("Color"), rs.stream.color, rs.format.rgb8, 3))
    profiles = [s.add_video_stream(_stream(k, i, f, b)) for i, (s, k, f, b) in enumerate(sensors)]
    sensors[0][0].add_read_only_option(rs.option.depth_units, 0.001)
    device.register_info(rs.camera_info.serial_number, "SW-7")
    device.register_info(rs.camera_info.name, "Software D435")
    if with_color:
        extrinsics = rs.extrinsics()
        extrinsics.rotation, extrinsics.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
        profiles[0].register_extrinsics_to(profiles[1], extrinsics)
    recorder = rs.recorder(str(path), device)
    queue = rs.frame_queue(100)
    for (sensor, *_), profile in zip(sensors, profiles, strict=True):
        sensor.open(profile)
        sensor.start(queue)
    for index in range(FRAMES):
        _push(sensors[0][0], profiles[0], np.full((H, W), 1000 + 10 * index, np.uint16), 2, index)
        if with_color:
            _push(sensors[1][0], profiles[1], np.full((H, W, 3), 10 * index, np.uint8), 3, index)
        # The recorder writes a frame before the sensor hands it on: once every frame of this
        # index has come through, it is in the file, and its slot in the sensor's pool is free.
        for _ in sensors:
            queue.wait_for_frame(SDK_WAIT_MS)
    recorder.pause()  # waits for the recorder's thread to write what it was handed
    for sensor, *_ in sensors:
        sensor.stop()
        sensor.close()
    del recorder  # closes the file


def frames_in(path: Path, expected: int) -> dict[Any, int]:
    """How many frames of each stream the recording holds (up to ``expected`` in all), read
    sensor by sensor without the pipeline's syncer, so that nothing is dropped on the way."""
    device = rs.context().load_device(str(path))
    device.as_playback().set_real_time(False)
    queue = rs.frame_queue(4 * FRAMES, keep_frames=True)
    sensors = device.query_sensors()
    for sensor in sensors:
        sensor.open(sensor.get_stream_profiles())
        sensor.start(queue)
    counts: dict[Any, int] = {}
    while sum(counts.values()) < expected:
        ok_frame = queue.try_wait_for_frame(SDK_WAIT_MS)
        if not ok_frame[0]:
            break
        kind = ok_frame[1].get_profile().stream_type()
        counts[kind] = counts.get(kind, 0) + 1
    for sensor in sensors:
        sensor.stop()
        sensor.close()
    return counts


def session_depth(session: Any, capture: Any) -> np.ndarray:
    from fieldapp.io.images import depth_units_to_m, read_depth_units

    return depth_units_to_m(read_depth_units(session.path_of(capture.depth)), 1000.0)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("bags")
    return {
        "color": record(folder / "color.db3", with_color=True),
        "depth": record(folder / "depth.db3", with_color=False),
    }


def test_colour_recording(recordings, tmp_path, capsys):
    out = tmp_path / "session"
    args = ["import", "bag", str(recordings["color"]), "--step-deg", "30", "--out", str(out)]
    assert main(args) == 0
    assert "depth-only" not in capsys.readouterr().out
    assert verify_session(out).usable
    session = load_session(out)
    camera = session.calibration.depth_camera
    assert (camera.width, camera.height, camera.fx, camera.cx) == (W, H, F, W / 2)
    assert len(session.captures) == FRAMES  # every recorded pair, however loaded the machine
    for capture in session.captures:
        assert capture.angle_deg == pytest.approx(30.0 * capture.view)
        images = session.read_capture(capture)
        index = int(images.color[0, 0, 0]) // 10
        inner = images.depth_m[4:-4, 4:-4]  # alignment leaves the border empty
        assert np.nanmax(np.abs(inner - (1.0 + 0.01 * index))) < 1e-3
        assert np.isfinite(inner).mean() > 0.95


def test_depth_only_recording_every_other_frame(recordings, tmp_path):
    out = tmp_path / "session"
    result = import_bag(recordings["depth"], out, BagOptions(every=2, max_views=3))
    assert result.captures == 3 and result.depth_only == 3
    assert any("no colour stream" in line for line in result.lines)
    assert verify_session(out).usable
    session = load_session(out)
    depths = [1000 * float(np.nanmedian(session_depth(session, c))) for c in session.captures]
    np.testing.assert_allclose(np.diff(depths), [20.0, 20.0], atol=1e-3)  # every other frame
    assert all(c.color is None for c in session.captures)


def test_what_is_not_a_recording_is_named(tmp_path):
    path = tmp_path / "empty.bag"
    path.write_bytes(b"not a bag")
    with pytest.raises(FieldappError, match=r"empty\.bag: the RealSense SDK cannot play it"):
        import_bag(path, tmp_path / "out", BagOptions())
    with pytest.raises(FieldappError, match="no such recording"):
        import_bag(tmp_path / "missing.bag", tmp_path / "out", BagOptions())


def test_a_sensor_started_late_loses_none_of_its_frames(recordings, tmp_path, monkeypatch):
    """The SDK plays the file as soon as the first sensor starts and drops the frames of a
    sensor not yet started. Here the reader is slow (room for two frames) and the colour
    sensor starts only once depth frames have filled that room (or a while has passed): every
    pair must still be imported, in order, and none twice."""
    from fieldapp.imports import bag

    started = bag._Playback._start_sensor

    def start_then_let_it_play(self, sensor):
        if sensor is self.opened[0]:
            self.queue = queue.Queue(maxsize=2)
        started(self, sensor)
        if len(self.opened) > 1 and sensor is self.opened[0]:
            for _ in range(50):  # a bounded poll for the depth frames, not a speed check
                if self.queue.full():
                    break
                threading.Event().wait(0.02)

    monkeypatch.setattr(bag._Playback, "_start_sensor", start_then_let_it_play)
    result = import_bag(recordings["color"], tmp_path / "session", BagOptions())
    assert not any("no partner" in line for line in result.lines), result.lines
    assert result.captures == FRAMES and result.depth_only == 0
    session = load_session(tmp_path / "session")
    grey = [int(session.read_capture(c).color[0, 0, 0]) for c in session.captures]
    assert grey == [10 * i for i in range(FRAMES)]


class _Stamped:
    def __init__(self, number: int, stamp_ms: float) -> None:
        self.number, self.stamp_ms = number, stamp_ms

    def get_frame_number(self) -> int:
        return self.number

    def get_timestamp(self) -> float:
        return self.stamp_ms


def test_only_a_frame_delivered_twice_is_skipped_not_a_clock_that_starts_over():
    from fieldapp.imports.bag import _Playback

    playback = object.__new__(_Playback)  # the bookkeeping alone, no SDK
    playback._last = {}
    frames = [(0, 0.0), (0, 0.0), (1, 33.3), (2, 66.6), (0, 0.0), (1, 33.3)]
    kept = [f for f in frames if not playback._repeated("depth", _Stamped(*f))]
    assert kept == [(0, 0.0), (1, 33.3), (2, 66.6), (0, 0.0), (1, 33.3)]
    assert not playback._repeated("color", _Stamped(0, 0.0))  # each stream on its own
