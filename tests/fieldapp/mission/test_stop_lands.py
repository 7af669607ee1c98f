"""STOP lands whatever the mission's thread is doing, and a thread that dies still ends the
mission with its reason. Timing runs on an injected clock; no wall-clock duration is asserted."""

from __future__ import annotations

import dataclasses
import json
import threading
from collections.abc import Callable
from typing import Any

import pytest

from devices.camera import DepthCamera, Frame
from fieldapp.mission import MissionRunner, MissionSetup, MissionState, Outcome
from fieldapp.mission.folder import STATUS_FILE

from .conftest import HANG_S, WrappedCamera, small_plan

Opener = Callable[..., MissionSetup]


class SteppingClock:
    """Each reading is ``step_s`` later than the last."""

    def __init__(self, step_s: float) -> None:
        self.now_s, self.step_s = 0.0, step_s
        self._lock = threading.Lock()

    def __call__(self) -> float:
        with self._lock:
            self.now_s += self.step_s
            return self.now_s


class BlockingCamera(WrappedCamera):
    """Wraps a camera; a read blocks until :attr:`release` is set (a hung USB transfer), or
    raises ``error`` when one is given."""

    def __init__(self, inner: DepthCamera, error: BaseException | None = None) -> None:
        super().__init__(inner)
        self.error = error
        self.entered, self.release = threading.Event(), threading.Event()

    def _read(self, timeout_s: float) -> Frame:
        self.entered.set()
        if self.error is not None:
            raise self.error
        assert self.release.wait(HANG_S), "never released"
        return self.inner.read_frame(timeout_s)


def runner_with(setup: MissionSetup, camera: DepthCamera, **options: Any) -> MissionRunner:
    rig = dataclasses.replace(setup.rig, camera=camera)
    return MissionRunner(setup.plan, rig, setup.writer, **options)


def status(setup: MissionSetup) -> dict[str, Any]:
    result: dict[str, Any] = json.loads((setup.folder / STATUS_FILE).read_text())
    return result


def test_stop_ends_the_mission_within_its_budget_even_when_a_device_call_hangs(
    open_mission: Opener,
) -> None:
    setup = open_mission(small_plan(stations=(5,), views=2))
    camera = BlockingCamera(setup.rig.camera)
    runner = runner_with(setup, camera, clock=SteppingClock(0.05))
    results: list[Any] = []
    runner.finished.connect(results.append)
    runner.start()
    assert camera.entered.wait(HANG_S)
    runner.stop()
    result = runner.wait(HANG_S)
    assert result is not None and result.outcome is Outcome.STOPPED
    assert runner.forced_end and runner.state is MissionState.FINISHED
    assert runner.stop_latency_s is not None and runner.stop_latency_s <= runner.stop_budget_s + 0.2
    assert status(setup)["state"] == "finished" and status(setup)["outcome"] == "stopped"
    assert setup.rig.sim_base is not None and setup.rig.sim_base.latched
    assert "still under way" in result.message

    assert not runner.join(0.0)  # still inside the camera call: a resume waits for it
    camera.release.set()  # the hung call returns: the late thread refreshes the status only
    assert runner.join(HANG_S)
    assert len(results) == 1 and runner.state is MissionState.FINISHED
    late = status(setup)
    assert late["state"] == "finished" and late["outcome"] == "stopped"
    assert late["missing"] == [list(key) for key in runner.missing()]


def test_stop_while_the_stop_helper_is_slow_to_start_still_ends_stopped(
    open_mission: Opener, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The old race: the helper was published before it started, and the mission's thread,
    ending first, joined a thread not yet started (RuntimeError, page stuck in STOPPING)."""
    setup = open_mission(small_plan(stations=(5,), views=2))
    mission_done = threading.Event()

    class SlowStart(threading.Thread):
        def start(self) -> None:
            if self.name == "mission-stop":
                mission_done.wait(2.0)  # the mission's thread runs to its end meanwhile
            super().start()

    monkeypatch.setattr("fieldapp.mission.runner.threading.Thread", SlowStart)
    runner = setup.runner()
    runner._ended = _SignallingEvent(mission_done)
    first = threading.Event()
    runner.view_captured.connect(lambda e: first.set())
    runner.start()
    assert first.wait(HANG_S)
    runner.stop()
    result = runner.wait(HANG_S)
    assert result is not None and result.outcome in (Outcome.STOPPED, Outcome.COMPLETE), result
    assert runner.state is MissionState.FINISHED
    assert status(setup)["state"] == "finished"


class _SignallingEvent(threading.Event):
    """An Event that also sets ``also`` when set."""

    def __init__(self, also: threading.Event) -> None:
        super().__init__()
        self.also = also

    def set(self) -> None:
        super().set()
        self.also.set()


class ThreadDeath(BaseException):
    """Not an Exception: what a broken library or an injected async exception could raise."""


@pytest.mark.parametrize("error", [ThreadDeath("injected"), MemoryError("injected")])
def test_a_mission_thread_that_dies_ends_failed_with_its_reason(
    open_mission: Opener, error: BaseException
) -> None:
    setup = open_mission(small_plan(stations=(5,), views=2))
    runner = runner_with(setup, BlockingCamera(setup.rig.camera, error=error))
    result = runner.start().wait(HANG_S)
    assert result is not None and result.outcome is Outcome.FAILED
    assert runner.state is MissionState.FAILED
    assert result.fault is not None and "injected" in result.fault.what
    assert status(setup)["state"] == "failed"


def test_stop_before_start_touches_no_device_and_ends_stopped(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    runner = setup.runner()
    runner.stop()
    result = runner.start().wait(HANG_S)
    assert result is not None and result.outcome is Outcome.STOPPED and result.captured == 0
    assert setup.rig.sim_base is not None and setup.rig.sim_base.latched  # not reset
