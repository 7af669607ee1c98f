"""Live streaming: a grabber thread reads the camera as fast as it delivers into a
latest-frame buffer (newest wins), so a slow consumer (a preview polling with a timer, a
quality check) never slows acquisition, and acquisition never waits for the consumer.

The stream measures the rate frames arrive at, how many frames were overwritten before any
consumer read them, and how many the camera itself skipped (gaps in ``meta["frame_number"]``).
An error in the grabber (timeout, unplugged) ends the stream and is raised to the consumer.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType

from devices.camera.base import FRAME_TIMEOUT_S, CameraError, CameraTimeout, DepthCamera
from devices.camera.frames import Frame

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StreamStats:
    """``frames`` grabbed, ``fps`` measured over the last ``window_s``, ``overwritten`` frames
    replaced unread, ``camera_dropped`` frames the camera skipped, ``reads`` by consumers."""

    frames: int
    fps: float
    overwritten: int
    camera_dropped: int
    reads: int


class LatestFrame:
    """A one-slot buffer: :meth:`put` replaces the frame and never blocks on a reader."""

    def __init__(self) -> None:
        self._condition = threading.Condition()
        self._frame: Frame | None = None
        self._sequence = 0
        self._read_sequence = 0
        self.overwritten = 0
        self.reads = 0

    @property
    def sequence(self) -> int:
        """How many frames were ever put (the newest frame's number)."""
        return self._sequence

    def put(self, frame: Frame) -> None:
        with self._condition:
            if self._frame is not None and self._read_sequence < self._sequence:
                self.overwritten += 1
            self._frame = frame
            self._sequence += 1
            self._condition.notify_all()

    def latest(self) -> tuple[int, Frame] | None:
        """(sequence, newest frame), or ``None`` before the first frame."""
        with self._condition:
            return self._take()

    def wait_newer(self, sequence: int, timeout_s: float) -> tuple[int, Frame] | None:
        """The newest frame once its sequence exceeds ``sequence``; ``None`` on timeout."""
        with self._condition:
            if not self._condition.wait_for(lambda: self._sequence > sequence, timeout_s):
                return None
            return self._take()

    def wake(self) -> None:
        """Wake every waiter (the stream ended)."""
        with self._condition:
            self._condition.notify_all()

    def _take(self) -> tuple[int, Frame] | None:
        if self._frame is None:
            return None
        self._read_sequence = self._sequence
        self.reads += 1
        return self._sequence, self._frame


class FrameStream:
    """Grabs frames from an open camera on a thread into a :class:`LatestFrame`."""

    def __init__(
        self,
        camera: DepthCamera,
        timeout_s: float = FRAME_TIMEOUT_S,
        window_s: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``clock`` times the frame rate and :meth:`next_frame`'s wait (a fake one in tests);
        the grabber's own wait is the camera's ``read_frame(timeout_s)``."""
        self.camera = camera
        self._clock = clock
        self.timeout_s = timeout_s
        self.window_s = window_s
        self.buffer = LatestFrame()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._arrivals: deque[float] = deque()
        self._lock = threading.Lock()
        self._frames = 0
        self._camera_dropped = 0
        self._last_number: int | None = None
        self._seen = 0
        self.error: CameraError | None = None
        self._error_traceback: TracebackType | None = None

    def start(self) -> FrameStream:
        if self._thread is None:
            self._thread = threading.Thread(target=self._grab, name="camera-grabber", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop grabbing; returns once the grabber has ended (within one frame timeout)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(self.timeout_s + 1.0)
            if self._thread.is_alive():
                log.warning("camera grabber still blocked in the driver after stop")
            self._thread = None
        self.buffer.wake()

    def __enter__(self) -> FrameStream:
        return self.start()

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def latest(self) -> Frame | None:
        """The newest frame (``None`` before the first); raises the grabber's error, if any."""
        self._raise_error()
        taken = self.buffer.latest()
        return None if taken is None else taken[1]

    def last_frame(self) -> Frame | None:
        """The newest frame the stream delivered, even after it ended (never raises)."""
        taken = self.buffer.latest()
        return None if taken is None else taken[1]

    def next_frame(self, timeout_s: float | None = None) -> Frame:
        """A frame newer than the last one this method returned; waits for it."""
        timeout_s = self.timeout_s if timeout_s is None else timeout_s
        deadline = self._clock() + timeout_s
        while True:
            self._raise_error()
            remaining = deadline - self._clock()
            taken = self.buffer.wait_newer(self._seen, min(max(remaining, 0.0), 0.1))
            if taken is not None:
                self._seen = taken[0]
                return taken[1]
            if remaining <= 0:
                raise CameraTimeout(f"no new frame from the stream within {timeout_s:.1f} s")

    def stats(self) -> StreamStats:
        with self._lock:
            arrivals = list(self._arrivals)
            frames, dropped = self._frames, self._camera_dropped
        span = arrivals[-1] - arrivals[0] if len(arrivals) > 1 else 0.0
        fps = (len(arrivals) - 1) / span if span > 0 else 0.0
        return StreamStats(frames, fps, self.buffer.overwritten, dropped, self.buffer.reads)

    def _raise_error(self) -> None:
        if self.error is not None:
            # Raised again on every call: from the grabber's traceback each time, or each
            # raise would add this call's frames to it and it would grow without end.
            raise self.error.with_traceback(self._error_traceback)

    def _grab(self) -> None:
        while not self._stop.is_set():
            try:
                frame = self.camera.read_frame(self.timeout_s)
            except CameraError as error:
                if not self._stop.is_set():
                    log.error("camera stream ended: %s", error)
                    self._error_traceback = error.__traceback__
                    self.error = error
                break
            self._count(frame)
            self.buffer.put(frame)
        self.buffer.wake()

    def _count(self, frame: Frame) -> None:
        now = self._clock()
        number = frame.meta.get("frame_number")
        with self._lock:
            self._frames += 1
            self._arrivals.append(now)
            while self._arrivals and now - self._arrivals[0] > self.window_s:
                self._arrivals.popleft()
            if isinstance(number, int):
                if self._last_number is not None and number > self._last_number + 1:
                    self._camera_dropped += number - self._last_number - 1
                self._last_number = number
