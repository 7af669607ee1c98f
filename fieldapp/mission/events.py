"""What a running mission tells its watchers: states, one event per step, progress, the result.

Events are small frozen dataclasses; the runner emits them as psygnal signals from its thread
(a GUI delivers them on its own thread). ``thumbnail`` images are (h, w, 3) uint8 RGB, about
64 x 53 pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from devices.camera.quality import QualityReport


class MissionState(StrEnum):
    IDLE = "idle"
    RUNNING = "running"
    PAUSED = "paused"
    STOPPING = "stopping"
    FINISHED = "finished"
    """Ended as planned: complete, or aborted/stopped by the operator."""
    FAILED = "failed"
    """Ended by a fault the retries could not overcome."""


class Outcome(StrEnum):
    COMPLETE = "complete"
    ABORTED = "aborted"
    STOPPED = "stopped"
    FAILED = "failed"


@dataclass(frozen=True)
class Fault:
    """What went wrong (``device``: base, table, camera), what happened, what to do."""

    device: str
    what: str
    advice: str

    def __str__(self) -> str:
        return f"{self.device}: {self.what}. What to do: {self.advice}"


@dataclass(frozen=True)
class StationReached:
    station: int
    x_m: float
    y_m: float
    yaw_deg: float
    """The pose the base reported on arrival (map frame)."""
    attempts: int


@dataclass(frozen=True)
class ViewCaptured:
    station: int
    view: int
    angle_deg: float
    """The table angle reached."""
    quality: QualityReport
    quality_ok: bool
    thumbnail: NDArray[np.uint8] = field(repr=False)
    attempts: int


@dataclass(frozen=True)
class MissionWarning:
    """Something went wrong and was handled (a retry), or needs the operator's attention."""

    text: str
    station: int | None = None
    view: int | None = None


@dataclass(frozen=True)
class MissionProgress:
    """``done`` of ``total`` captures; ``remaining_s`` is ``None`` until a view was timed."""

    done: int
    total: int
    elapsed_s: float
    remaining_s: float | None
    step: str

    @property
    def fraction(self) -> float:
        return self.done / self.total if self.total else 1.0


@dataclass(frozen=True)
class MissionResult:
    """How the mission ended and what the session still misses (plan order)."""

    outcome: Outcome
    captured: int
    missing: list[tuple[int, int]]
    fault: Fault | None = None
    message: str = ""

    @property
    def complete(self) -> bool:
        return self.outcome is Outcome.COMPLETE

    def lines(self) -> list[str]:
        """The operator's summary: what happened, what is missing, what to do."""
        lines = [f"mission {self.outcome.value}: {self.captured} captures taken"]
        if self.message:
            lines.append(self.message)
        if self.missing:
            listed = ", ".join(f"s{s} v{v}" for s, v in self.missing)
            lines.append(f"missing ({len(self.missing)}): {listed}")
        if self.fault is not None:
            lines.append(f"what happened: {self.fault.device}: {self.fault.what}")
            lines.append(f"what to do: {self.fault.advice}")
        return lines


MissionEvent = StationReached | ViewCaptured | MissionWarning | MissionProgress
