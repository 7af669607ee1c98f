"""Kinematics of the simulated table: a planner queue of moves run with a trapezoid profile.

Each queued move starts and ends at rest, runs at its rate (deg/s) at most, and accelerates and
brakes at the acceleration of Grbl's ``$120`` (deg/s^2). A feed hold brakes to a stop and keeps
the rest of the move for the resume. ``advance(math.inf)`` runs everything queued at once.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

MAX_STEP_S = 0.002
"""Integration step of the motion, seconds."""

ARRIVED_DEG = 1e-6


@dataclass
class MoveBlock:
    """One planned move of the X (table) axis."""

    target_deg: float
    rate_deg_s: float
    homing: bool = False


class MotionModel:
    """Planner buffer plus the moving table. Not thread-safe: the simulator serialises calls."""

    def __init__(
        self,
        accel_deg_s2: float,
        capacity: int = 15,
        settle_offset_deg: Callable[[], float] = lambda: 0.0,
    ) -> None:
        self.accel_deg_s2 = accel_deg_s2
        self.capacity = capacity
        self.position_deg = 0.0
        self.velocity_deg_s = 0.0
        self.held = False
        self.stall_after_deg: float | None = None
        self.blocks: deque[MoveBlock] = deque()
        self._settle_offset_deg = settle_offset_deg
        self._travelled_deg = 0.0

    @property
    def full(self) -> bool:
        return len(self.blocks) >= self.capacity

    @property
    def idle(self) -> bool:
        """Nothing queued and at rest."""
        return not self.blocks and self.velocity_deg_s == 0.0

    @property
    def homing(self) -> bool:
        return bool(self.blocks) and self.blocks[0].homing

    def inject_stall(self, after_deg: float) -> None:
        """The motor stalls once the table has turned ``after_deg`` more degrees."""
        self.stall_after_deg = max(after_deg, 0.0)
        self._travelled_deg = 0.0

    def push(self, block: MoveBlock) -> None:
        self.blocks.append(block)

    def stop_now(self) -> None:
        """Abrupt stop (reset, hard limit): the queue is dropped, the table stays where it is."""
        self.blocks.clear()
        self.velocity_deg_s = 0.0
        self.held = False

    def advance(self, dt_s: float) -> bool:
        """Run the motion for ``dt_s`` seconds; True when an injected stall stopped it."""
        if math.isinf(dt_s):
            return self._finish_all()
        remaining_s = dt_s
        while remaining_s > 0.0 and self.blocks:
            step_s = min(remaining_s, MAX_STEP_S)
            remaining_s -= step_s
            if self._step(step_s):
                return True
        return False

    def _finish_all(self) -> bool:
        while self.blocks and not self.held:
            block = self.blocks[0]
            distance_deg = abs(block.target_deg - self.position_deg)
            if self._stall_within(distance_deg, block.target_deg):
                return True
            self._complete(block)
        if self.held:
            self.velocity_deg_s = 0.0
        return False

    def _step(self, step_s: float) -> bool:
        block = self.blocks[0]
        distance_deg = abs(block.target_deg - self.position_deg)
        v0 = self.velocity_deg_s
        if self.held:
            v1 = max(0.0, v0 - self.accel_deg_s2 * step_s)
        else:
            braking = math.sqrt(2.0 * self.accel_deg_s2 * distance_deg)
            v1 = min(block.rate_deg_s, v0 + self.accel_deg_s2 * step_s, braking)
        travel_deg = min(0.5 * (v0 + v1) * step_s, distance_deg)
        if self._stall_within(travel_deg, block.target_deg):
            return True
        if not self.held and distance_deg - travel_deg <= ARRIVED_DEG:
            self._complete(block)
            return False
        self.position_deg += math.copysign(travel_deg, block.target_deg - self.position_deg)
        self._travelled_deg += travel_deg
        self.velocity_deg_s = v1
        return False

    def _stall_within(self, travel_deg: float, target_deg: float) -> bool:
        if self.stall_after_deg is None:
            return False
        left_deg = self.stall_after_deg - self._travelled_deg
        if travel_deg < left_deg:
            return False
        self.position_deg += math.copysign(max(left_deg, 0.0), target_deg - self.position_deg)
        self.stall_after_deg = None
        self._travelled_deg = 0.0
        self.stop_now()
        return True

    def _complete(self, block: MoveBlock) -> None:
        self._travelled_deg += abs(block.target_deg - self.position_deg)
        offset_deg = 0.0 if block.homing else self._settle_offset_deg()
        self.position_deg = block.target_deg + offset_deg
        self.velocity_deg_s = 0.0
        self.blocks.popleft()
