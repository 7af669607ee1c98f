"""What the protocol server drives: a navigation backend (the simulator's motion model, or ROS).

The server owns the protocol state (goal, stop latch, watchdog); a backend only starts goals,
halts, and reports where the base is and how navigation is going.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Protocol

from devices.base.protocol import Goal, Pose


class NavProgress(StrEnum):
    IDLE = "idle"
    MOVING = "moving"
    ARRIVED = "arrived"
    ABORTED = "aborted"


class GoalRefused(Exception):
    """The navigation stack refused a goal at once (answered as ``nav_failed``)."""


@dataclass(frozen=True)
class BackendSnapshot:
    pose: Pose
    progress: NavProgress
    battery_pct: float
    error: str | None = None


class MotionBackend(Protocol):
    """The motion side of a base. All calls come from the server's loop thread."""

    def begin_goal(self, goal: Goal) -> None:
        """Start navigating to ``goal`` (raises :class:`GoalRefused`)."""

    def halt(self) -> None:
        """Cancel any goal and command zero velocity now."""

    def update(self) -> BackendSnapshot:
        """Advance (for a simulator) and report the current pose and progress."""
        ...
