"""The base's protocol state machine on its own: no sockets, and the time is the test's."""

from __future__ import annotations

import pytest

from devices.base.backend import BackendSnapshot, NavProgress
from devices.base.controller import LINK_LOST, BaseController, ControllerConfig
from devices.base.protocol import BaseState, Command, Goal, Pose, Request


class FakeBackend:
    """A base that drives as long as it has a goal; counts halts."""

    def __init__(self) -> None:
        self.goals: list[Goal] = []
        self.halts = 0
        self.progress = NavProgress.IDLE

    def begin_goal(self, goal: Goal) -> None:
        self.goals.append(goal)
        self.progress = NavProgress.MOVING

    def halt(self) -> None:
        self.halts += 1
        self.progress = NavProgress.IDLE

    def update(self) -> BackendSnapshot:
        return BackendSnapshot(Pose(0.0, 0.0, 0.0), self.progress, 90.0)


def _goto(base: BaseController, goal_id: str = "g") -> Request:
    args = {"goal_id": goal_id, "x": 1.0, "y": 0.0, "yaw_deg": 0.0}
    return Request(f"c-{goal_id}", Command.GOTO, args, base.session)


@pytest.fixture
def controller() -> tuple[BaseController, FakeBackend]:
    backend = FakeBackend()
    return BaseController(backend, ControllerConfig(watchdog_s=1.0)), backend


@pytest.mark.parametrize("start_s", [0.0, 12.5, 1.0e6])
def test_watchdog_fires_just_after_its_period_of_silence(
    controller: tuple[BaseController, FakeBackend], start_s: float
) -> None:
    base, backend = controller
    assert base.handle(_goto(base), start_s).ok
    base.tick(start_s + 0.6)
    assert base.handle(Request("c-hb", Command.HEARTBEAT), start_s + 0.6).ok
    base.tick(start_s + 1.6)  # exactly 1.0 s after the last request: not yet
    assert base.status().state is BaseState.MOVING and backend.halts == 0
    base.tick(start_s + 1.61)
    assert base.status().state is BaseState.STOPPED
    assert base.status().error == LINK_LOST
    assert backend.halts == 1 and base.latched


def test_watchdog_sleeps_without_a_goal(controller: tuple[BaseController, FakeBackend]) -> None:
    base, backend = controller
    base.tick(0.0)
    base.tick(1.0e4)
    assert base.status().state is BaseState.IDLE and backend.halts == 0
