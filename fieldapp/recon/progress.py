"""What the reconstruction reports while it runs, and how long each stage took."""

from __future__ import annotations

import resource
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Progress:
    """One progress event: the stage running, the overall fraction done (0-1), a message."""

    stage: str
    fraction: float
    message: str


STAGES = {
    "local reconstruction": (0.00, 0.40),
    "levelling": (0.40, 0.45),
    "filtering": (0.45, 0.70),
    "registration": (0.70, 0.90),
    "plants": (0.90, 0.98),
    "traits": (0.98, 1.00),
}
"""Each stage's share of the overall fraction (start, end)."""


def progress(stage: str, done: float, message: str) -> Progress:
    """A :class:`Progress` for ``done`` (0-1) of ``stage``."""
    start, end = STAGES[stage]
    return Progress(stage, start + (end - start) * min(max(done, 0.0), 1.0), message)


@dataclass
class StageTimer:
    """Wall time and CPU time (all threads of the process, and of the child processes a stage
    started and waited for: registration's worker) per stage in seconds, accumulated over
    every call of :meth:`stage`. On a shared machine the CPU time is the steadier figure. A
    stage run inside another (a station levelled and filtered as soon as it is read) counts
    only as itself: the outer stage's clock stops meanwhile."""

    seconds: dict[str, float] = field(default_factory=dict)
    cpu_seconds: dict[str, float] = field(default_factory=dict)
    _open: list[str] = field(default_factory=list, repr=False)
    _since: tuple[float, float] = field(default=(0.0, 0.0), repr=False)

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        self._lap()
        self._open.append(name)
        try:
            yield
        finally:
            self._lap()
            self._open.pop()

    def _lap(self) -> None:
        """The time since the last lap to the stage running (if any); a new lap starts."""
        now = (time.perf_counter(), cpu_seconds())
        if self._open:
            name = self._open[-1]
            self.seconds[name] = self.seconds.get(name, 0.0) + now[0] - self._since[0]
            self.cpu_seconds[name] = self.cpu_seconds.get(name, 0.0) + now[1] - self._since[1]
        self._since = now


def cpu_seconds() -> float:
    """CPU seconds of this process and of its children that ended and were waited for."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime
