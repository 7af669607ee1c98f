"""A monotonic clock for timing logic under test: it moves only when the test says so.

Drivers and servers take ``clock: Callable[[], float]`` (``time.monotonic`` by default); a test
hands them a :class:`FakeClock` and advances it, so watchdogs, timeouts and retries are checked
in the clock's seconds whatever the machine's load. Code that also sleeps on the clock is given
:meth:`FakeClock.sleep`, which advances the clock instead of waiting.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class FakeClock:
    """Thread-safe fake ``time.monotonic``."""

    def __init__(self, start_s: float = 1000.0) -> None:
        self._now_s = start_s
        self._lock = threading.Lock()
        self.reads = 0
        """How many times the clock was read: a test waits for the code under test to have
        taken the time (e.g. set its deadline) before it advances the clock."""

    def __call__(self) -> float:
        with self._lock:
            self.reads += 1
            return self._now_s

    def advance(self, seconds: float) -> float:
        """Move the clock on by ``seconds``; returns the new time."""
        with self._lock:
            self._now_s += seconds
            return self._now_s

    def sleep(self, seconds: float) -> None:
        """A ``time.sleep`` that advances the clock (and yields the thread)."""
        self.advance(max(seconds, 0.0))
        time.sleep(0)


def wait_real(predicate: Callable[[], bool], timeout_s: float = 20.0) -> bool:
    """Wait in real time, generously, for something driven by other threads to happen."""
    deadline_s = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline_s:
            return False
        time.sleep(0.005)
    return True
