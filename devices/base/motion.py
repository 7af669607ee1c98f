"""Motion model of the simulated base: a differential-drive robot driven like move_base.

To reach a goal it turns on the spot towards it, drives straight, then turns to the goal's yaw,
within speed and turn-rate limits. It stops a few centimetres and 1-2 degrees off the goal
(seeded), like AMCL + move_base within their goal tolerances. The battery drains per metre driven
and per second of operation (:class:`BatteryDrain`): a field robot of this class runs about 8 h
standing and 1.5 h driving. Faults: a blocked path (the base stops, then navigation gives up)
and a navigation failure (no plan). Pure model: time advances only through :meth:`MotionModel.step`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from devices.base.backend import NavProgress
from devices.base.protocol import Pose


class MotionFault(StrEnum):
    BLOCKED_PATH = "blocked_path"
    NAV_FAILURE = "nav_failure"


class _Phase(StrEnum):
    TURN_TO_PATH = "turn_to_path"
    DRIVE = "drive"
    TURN_TO_GOAL = "turn_to_goal"


@dataclass(frozen=True)
class BatteryDrain:
    """How the battery drains: per second of operation (computer, sensors, camera: 12 %/h, about
    8 h standing) and per metre driven (motors: 0.05 %/m, 54 %/h more at 0.3 m/s, about 1.5 h
    driving). Both count simulated time, whatever the time scale."""

    pct_per_s: float = 12.0 / 3600.0
    pct_per_m: float = 0.05

    def drained_pct(self, operating_s: float, driven_m: float) -> float:
        return self.pct_per_s * operating_s + self.pct_per_m * driven_m


@dataclass(frozen=True)
class MotionLimits:
    max_speed_m_s: float = 0.3
    max_turn_rate_deg_s: float = 45.0
    arrival_error_m: tuple[float, float] = (0.01, 0.04)
    arrival_error_deg: tuple[float, float] = (1.0, 2.0)
    battery: BatteryDrain = field(default_factory=lambda: BatteryDrain())
    blocked_timeout_s: float = 5.0
    """How long navigation waits at an obstacle before giving up (move_base recovery)."""
    plan_failure_delay_s: float = 0.5


def wrap_deg(angle_deg: float) -> float:
    """Angle in (-180, 180]."""
    wrapped = math.fmod(angle_deg + 180.0, 360.0)
    if wrapped <= 0.0:
        wrapped += 360.0
    return wrapped - 180.0


class MotionModel:
    """Pose, battery and navigation progress of a simulated base."""

    def __init__(
        self,
        limits: MotionLimits | None = None,
        start: Pose | None = None,
        seed: int = 0,
        battery_pct: float = 100.0,
    ) -> None:
        self.limits = limits or MotionLimits()
        self.pose = start or Pose(0.0, 0.0, 0.0)
        self.battery_pct = battery_pct
        self.progress = NavProgress.IDLE
        self.error: str | None = None
        self.faults: set[MotionFault] = set()
        self._rng = np.random.default_rng(seed)
        self._target: Pose | None = None
        self._phase = _Phase.TURN_TO_PATH
        self._stuck_s = 0.0

    def set_goal(self, goal: Pose) -> None:
        """Start towards ``goal``; the pose actually reached is a few cm and 1-2 deg off."""
        low_m, high_m = self.limits.arrival_error_m
        low_deg, high_deg = self.limits.arrival_error_deg
        direction = self._rng.uniform(0.0, 2.0 * math.pi)
        offset_m = self._rng.uniform(low_m, high_m)
        offset_deg = self._rng.uniform(low_deg, high_deg) * self._rng.choice([-1.0, 1.0])
        self._target = Pose(
            goal.x_m + offset_m * math.cos(direction),
            goal.y_m + offset_m * math.sin(direction),
            wrap_deg(goal.yaw_deg + offset_deg),
        )
        self._phase = _Phase.TURN_TO_PATH
        self._stuck_s = 0.0
        self.progress = NavProgress.MOVING
        self.error = None

    def halt(self) -> None:
        """Zero velocity at once; the goal is dropped."""
        self._target = None
        if self.progress is NavProgress.MOVING:
            self.progress = NavProgress.IDLE

    def step(self, dt_s: float, idle_speedup: float = 1.0) -> None:
        """Advance the model by ``dt_s`` seconds of simulated motion time.

        ``idle_speedup``: how much faster than the operation around it the motion runs (a fast
        simulation's time scale). Standing time is the operation's own time (the table turning,
        the camera capturing), so it drains the battery divided by ``idle_speedup``; moving
        time drains in full. The battery thus lasts the same hours of operation at any scale."""
        moved_s = 0.0
        if self._target is not None and self.progress is NavProgress.MOVING:
            if MotionFault.NAV_FAILURE in self.faults:
                reason = "no valid plan to goal"
                self._wait_then_abort(dt_s, self.limits.plan_failure_delay_s, reason)
            else:
                remaining_s = dt_s
                while remaining_s > 0.0 and self._target is not None:
                    remaining_s = self._advance(self._target, remaining_s)
                moved_s = dt_s - remaining_s
        operating_s = moved_s + (dt_s - moved_s) / max(idle_speedup, 1.0)
        self._drain(operating_s, 0.0)

    def _drain(self, operating_s: float, driven_m: float) -> None:
        drained_pct = self.limits.battery.drained_pct(operating_s, driven_m)
        self.battery_pct = max(0.0, self.battery_pct - drained_pct)

    def _wait_then_abort(self, dt_s: float, limit_s: float, reason: str) -> None:
        self._stuck_s += dt_s
        if self._stuck_s >= limit_s:
            self._target = None
            self.progress = NavProgress.ABORTED
            self.error = reason

    def _advance(self, target: Pose, dt_s: float) -> float:
        """Spend up to ``dt_s`` in the current phase; returns the time left over."""
        dx, dy = target.x_m - self.pose.x_m, target.y_m - self.pose.y_m
        distance_m = math.hypot(dx, dy)
        if self._phase is _Phase.TURN_TO_PATH:
            if distance_m < 1e-6:
                self._phase = _Phase.DRIVE
                return dt_s
            return self._turn_towards(math.degrees(math.atan2(dy, dx)), dt_s, _Phase.DRIVE)
        if self._phase is _Phase.DRIVE:
            return self._drive(dx, dy, distance_m, dt_s)
        left_s = self._turn_towards(target.yaw_deg, dt_s, None)
        if self._target is None:
            self.progress = NavProgress.ARRIVED
        return left_s

    def _turn_towards(self, heading_deg: float, dt_s: float, next_phase: _Phase | None) -> float:
        delta_deg = wrap_deg(heading_deg - self.pose.yaw_deg)
        needed_s = abs(delta_deg) / self.limits.max_turn_rate_deg_s
        if needed_s > dt_s:
            turn_deg = math.copysign(self.limits.max_turn_rate_deg_s * dt_s, delta_deg)
            self.pose = Pose(self.pose.x_m, self.pose.y_m, wrap_deg(self.pose.yaw_deg + turn_deg))
            return 0.0
        self.pose = Pose(self.pose.x_m, self.pose.y_m, wrap_deg(heading_deg))
        if next_phase is None:
            self._target = None
        else:
            self._phase = next_phase
        return dt_s - needed_s

    def _drive(self, dx: float, dy: float, distance_m: float, dt_s: float) -> float:
        if MotionFault.BLOCKED_PATH in self.faults:
            self._wait_then_abort(dt_s, self.limits.blocked_timeout_s, "path blocked")
            return 0.0
        step_m = self.limits.max_speed_m_s * dt_s
        fraction = 1.0 if distance_m <= step_m else step_m / distance_m
        self.pose = Pose(
            self.pose.x_m + dx * fraction, self.pose.y_m + dy * fraction, self.pose.yaw_deg
        )
        self._drain(0.0, distance_m * fraction)
        if fraction < 1.0:
            return 0.0
        self._phase = _Phase.TURN_TO_GOAL
        return dt_s - distance_m / self.limits.max_speed_m_s
