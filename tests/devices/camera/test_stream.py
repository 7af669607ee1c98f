"""The live stream: newest frame wins, counts of overwritten and skipped frames, errors."""

from __future__ import annotations

import threading
import time
import traceback

import numpy as np
import pytest

from devices.camera.base import CameraDisconnected, CameraInfo, CameraTimeout, DepthCamera
from devices.camera.frames import KINECT_V2_PAPER, Frame, Intrinsics
from devices.camera.stream import FrameStream, LatestFrame

from ..fake_clock import FakeClock


def _frame(number: int) -> Frame:
    depth = np.full((2, 2), float(number), np.float32)
    return Frame(depth, np.zeros((2, 2, 3), np.uint8), meta={"frame_number": number})


class ScriptedCamera(DepthCamera):
    """Hands out frames numbered by ``numbers``; then fails with ``error`` (default: blocks
    until its timeout, then :class:`CameraTimeout`). ``gate`` lets the test release frames."""

    def __init__(self, numbers: list[int], error: Exception | None = None) -> None:
        super().__init__()
        self.numbers = list(numbers)
        self.error = error
        self.gate = threading.Semaphore(0)

    @property
    def intrinsics(self) -> Intrinsics:
        return KINECT_V2_PAPER

    @property
    def info(self) -> CameraInfo:
        return CameraInfo("scripted", "test", "0")

    def _open(self) -> None:
        pass

    def _close(self) -> None:
        pass

    def _read(self, timeout_s: float) -> Frame:
        if not self.numbers:
            if self.error is not None:
                raise self.error
            time.sleep(timeout_s)
            raise CameraTimeout(f"no frame for {timeout_s} s")
        if not self.gate.acquire(timeout=timeout_s):
            raise CameraTimeout("gate closed")
        return _frame(self.numbers.pop(0))


def test_latest_frame_newest_wins_and_counts_unread() -> None:
    buffer = LatestFrame()
    assert buffer.latest() is None
    for n in range(3):
        buffer.put(_frame(n))
    taken = buffer.latest()
    assert taken is not None and taken[0] == 3 and taken[1].meta["frame_number"] == 2
    assert buffer.overwritten == 2  # frames 0 and 1 were never read
    buffer.put(_frame(3))  # frame 2 was read: not counted
    assert buffer.overwritten == 2
    assert buffer.wait_newer(3, 0.5) is not None
    assert buffer.wait_newer(4, 0.01) is None


def test_slow_consumer_never_slows_the_grabber() -> None:
    camera = ScriptedCamera(list(range(40)))
    with camera, FrameStream(camera, timeout_s=1.0) as stream:
        for _ in range(40):
            camera.gate.release()  # the camera delivers all 40 frames at once
        deadline = time.monotonic() + 20  # generous: waiting, not timing
        while stream.stats().frames < 40 and time.monotonic() < deadline:
            time.sleep(0.005)
        latest = stream.latest()
        stats = stream.stats()
    assert stats.frames == 40
    assert latest is not None and latest.meta["frame_number"] == 39
    assert stats.overwritten >= 30  # the consumer read (almost) none of them
    assert stats.camera_dropped == 0


def test_skipped_camera_frames_are_counted_and_fps_measured() -> None:
    numbers = [0, 1, 2, 5, 6, 10]
    camera = ScriptedCamera(numbers)
    clock = FakeClock()
    with camera, FrameStream(camera, timeout_s=2.0, clock=clock) as stream:
        seen = []
        for _ in numbers:
            clock.advance(0.02)
            camera.gate.release()
            seen.append(stream.next_frame(10.0).meta["frame_number"])
        stats = stream.stats()
    assert seen == numbers
    assert stats.camera_dropped == 2 + 3
    assert stats.fps == pytest.approx(50.0)  # a frame every 20 ms of the stream's clock


def _ended(stream: FrameStream) -> FrameStream:
    """``stream`` once its grabber has stopped (waiting generously, not timing)."""
    deadline = time.monotonic() + 20
    while stream.running and time.monotonic() < deadline:
        time.sleep(0.005)
    assert not stream.running
    return stream


def test_grabber_error_reaches_the_consumer() -> None:
    camera = ScriptedCamera([0], error=CameraDisconnected("unplugged"))
    camera.gate.release()
    with camera, FrameStream(camera, timeout_s=1.0) as started:
        stream = _ended(started)
        with pytest.raises(CameraDisconnected, match="unplugged"):
            stream.latest()
        with pytest.raises(CameraDisconnected):
            stream.next_frame(0.5)
        assert stream.last_frame() is not None  # the end stays on screen


def test_the_error_raised_again_and_again_keeps_its_traceback_short() -> None:
    camera = ScriptedCamera([0], error=CameraDisconnected("unplugged"))
    camera.gate.release()
    with camera, FrameStream(camera, timeout_s=1.0) as started:
        stream = _ended(started)
        depths = []
        for _ in range(50):  # a live view polls a dead stream like this
            with pytest.raises(CameraDisconnected) as raised:
                stream.latest()
            depths.append(len(traceback.extract_tb(raised.value.__traceback__)))
        assert depths[-1] == depths[0]


def test_no_frames_times_out_without_hanging() -> None:
    camera = ScriptedCamera([])
    with camera, FrameStream(camera, timeout_s=0.3) as stream, pytest.raises(CameraTimeout):
        stream.next_frame(60.0)  # the grabber's timeout ends the wait, not this one
    assert isinstance(stream.error, CameraTimeout)


def test_next_frame_gives_up_at_its_own_timeout() -> None:
    camera = ScriptedCamera([0], error=CameraDisconnected("end of script"))
    clock = FakeClock()
    with camera, FrameStream(camera, timeout_s=60.0, clock=clock) as stream:
        waiter_error: list[BaseException] = []

        def wait() -> None:
            try:
                stream.next_frame(2.0)
            except BaseException as error:
                waiter_error.append(error)

        waiter = threading.Thread(target=wait)
        waiter.start()
        clock.advance(1.99)
        time.sleep(0.2)
        assert waiter.is_alive()
        clock.advance(0.02)
        waiter.join(timeout=20.0)
        camera.gate.release()  # the grabber ends at once
    assert len(waiter_error) == 1 and isinstance(waiter_error[0], CameraTimeout)
    assert "no new frame from the stream within 2.0 s" in str(waiter_error[0])
