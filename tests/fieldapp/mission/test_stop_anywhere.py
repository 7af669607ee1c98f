"""STOP lands from any moment of a mission: driving, turning, capturing, saving, paused,
resuming, at a retry. Each trial STOPs a fast simulated mission at a random (seeded) moment; every
one must end stopped (or complete, when the STOP came after the last write) and consistent: the
runner in a terminal state, ``mission-status.json`` saying the same, the base and the table at
rest, the session folder verifying, and what the status lists as missing what the session misses.

The moments are chosen by call, not by time: the k-th call the mission makes to a device, to
the session writer or to the settle wait (k drawn from the seeded generator) triggers the STOP
before the call, from another thread while the call runs (a STOP during the settle wait wakes
the mission's thread while the stop helper starts: the race that used to leave the mission
joining an unstarted helper), or turns into a pause (then STOP while paused, or resume
and STOP at once). Some trials make the camera time out so the STOP lands at a retry. The rig
(simulated base over ZeroMQ, simulated Grbl table on a pty, both instant) stays open across
trials like the GUI's; the camera returns one pre-rendered frame, so a trial costs little more
than its session writes.
"""

from __future__ import annotations

import dataclasses
import json
import os
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from devices.base.protocol import BaseState
from devices.camera import CameraInfo, CameraTimeout, DepthCamera, Frame, Intrinsics
from devices.sim.world import SimWorld
from fieldapp.io.session import load_session
from fieldapp.mission import MissionRunner, MissionSetup, MissionState, Outcome, new_mission
from fieldapp.mission.calibration import calibration_in_force
from fieldapp.mission.folder import STATUS_FILE, missing_keys, start_session
from fieldapp.mission.plan import MissionPlan
from fieldapp.verify import verify_session

from .conftest import HANG_S, small_plan

# more by hand; fewer than 35 may miss a kind of moment (asserted below)
TRIALS_PER_SEED = int(os.environ.get("FIELDAPP_STOP_TRIALS", "35"))
SEEDS = (0, 1, 2, 3)
TAPPED = {
    "base": ("goto", "follow_goal", "status", "reset"),
    "table": ("goto_deg", "status", "resume"),
    "camera": ("capture",),
    "writer": ("add_capture",),
}


class InstantCamera(DepthCamera):
    """One frame rendered by the simulated camera, returned at once with a fresh timestamp;
    ``timeouts``: read numbers (1-based) that time out instead."""

    def __init__(self, frame: Frame, intrinsics: Intrinsics, info: CameraInfo) -> None:
        super().__init__()
        self.frame, self._intrinsics, self._info = frame, intrinsics, info
        self.timeouts: set[int] = set()
        self.reads = 0
        self._is_open = True

    @property
    def intrinsics(self) -> Intrinsics:
        return self._intrinsics

    @property
    def info(self) -> CameraInfo:
        return self._info

    def _open(self) -> None: ...

    def _close(self) -> None: ...

    def _read(self, timeout_s: float) -> Frame:
        self.reads += 1
        if self.reads in self.timeouts:
            raise CameraTimeout(f"no frame within {timeout_s:.1f} s (injected)")
        return dataclasses.replace(self.frame, timestamp_s=time.monotonic(), meta={})


class Tap:
    """Passes every attribute of ``inner`` through; calls of ``names`` made on the mission's
    thread are counted and announced to ``hook(label, number, call)`` first, which makes the
    call (``call()``) and returns its result."""

    def __init__(self, inner: Any, label: str, names: tuple[str, ...], hook: Any) -> None:
        self._inner, self._label, self._names, self._hook = inner, label, names, hook

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._inner, name)
        if name not in self._names or not callable(value):
            return value

        def tapped(*args: Any, **kwargs: Any) -> Any:
            if threading.current_thread().name != "mission":
                return value(*args, **kwargs)
            return self._hook(f"{self._label}.{name}", lambda: value(*args, **kwargs))

        return tapped


@dataclasses.dataclass
class Moment:
    """Where a trial STOPs: at mission call ``call`` (1-based), in the manner ``how``."""

    call: int
    how: str  # before | during | pause | resume
    camera_timeout: int | None = None


class Trial:
    """One mission on the shared rig, stopped at ``moment``."""

    def __init__(self, rig_setup: MissionSetup, plan: MissionPlan, folder: Path, moment: Moment):
        self.moment = moment
        self.calls = 0
        self.labels: list[str] = []
        self.stop_thread: threading.Thread | None = None
        rig = rig_setup.rig
        camera = rig.camera
        assert isinstance(camera, InstantCamera)
        camera.reads = 0
        camera.timeouts = {moment.camera_timeout} if moment.camera_timeout else set()
        writer = start_session(folder, plan, calibration_in_force(plan, rig.world))
        self.tapped_rig = dataclasses.replace(
            rig,
            base=Tap(rig.base, "base", TAPPED["base"], self.hook),
            table=Tap(rig.table, "table", TAPPED["table"], self.hook),
            camera=Tap(camera, "camera", TAPPED["camera"], self.hook),
        )
        self.writer = writer
        self.runner = MissionRunner(plan, self.tapped_rig, Tap(writer, "writer",  # type: ignore[arg-type]
                                    TAPPED["writer"], self.hook))  # fmt: skip
        sleep = self.runner.gate.sleep  # the settle wait: a STOP wakes the sleeping thread

        def tapped_sleep(seconds: float) -> None:
            self.hook("gate.sleep", lambda: sleep(seconds))

        self.runner.gate.sleep = tapped_sleep  # type: ignore[method-assign]

    def hook(self, label: str, call: Callable[[], Any]) -> Any:
        self.calls += 1
        self.labels.append(label)
        if self.calls != self.moment.call:
            return call()
        how = self.moment.how
        if how == "before":
            self.runner.stop()
        elif how == "during":
            self.stop_thread = threading.Thread(target=self.runner.stop, name="operator")
            self.stop_thread.start()
        else:  # pause (and resume): the mission pauses at its next checkpoint
            self.runner.pause()
            self.stop_thread = threading.Thread(target=self._stop_when_paused, name="operator")
            self.stop_thread.start()
        return call()

    def _stop_when_paused(self) -> None:
        deadline_s = time.monotonic() + HANG_S
        while self.runner.state is MissionState.RUNNING and time.monotonic() < deadline_s:
            time.sleep(0.002)
        if self.moment.how == "resume":
            self.runner.resume()
        self.runner.stop()


@pytest.fixture(scope="module")
def shared_rig(
    tmp_path_factory: pytest.TempPathFactory, sim_world: SimWorld
) -> Iterator[MissionSetup]:
    """One open simulated rig (instant base and table) with an instant camera."""
    sim_world.set_base_pose(1.6, 1.6, 0.0)
    folder = tmp_path_factory.mktemp("rig") / "first"
    setup = new_mission(small_plan(), folder, realtime=False, world=sim_world)
    # instant devices answer at once: poll them often, as the moments are counted in calls
    # and a drive's or a turn's polls would otherwise be most of a trial's time
    base, table = setup.rig.base, setup.rig.table
    base.timing = dataclasses.replace(base.timing, status_poll_period_s=0.01)
    table.timeouts = dataclasses.replace(table.timeouts, poll_s=0.02)
    camera = setup.rig.camera
    frame = camera.capture(1, 10.0)
    instant = InstantCamera(frame, camera.intrinsics, camera.info)
    yield dataclasses.replace(setup, rig=dataclasses.replace(setup.rig, camera=instant))
    setup.close()


def moments(seed: int, count: int) -> list[Moment]:
    """``count`` seeded moments over a 2-station, 2-view mission (about 35 tapped calls)."""
    rng = np.random.default_rng(seed)
    result = []
    for _ in range(count):
        how = str(rng.choice(["before", "during", "during", "pause", "resume"]))
        timeout = int(rng.integers(1, 5)) if rng.random() < 0.25 else None
        result.append(Moment(int(rng.integers(1, 38)), how, timeout))
    return result


def check_consistent(trial: Trial, folder: Path, rig: MissionSetup) -> str:
    """Assert the trial ended stopped and consistent; returns its outcome."""
    runner = trial.runner
    result = runner.wait(HANG_S)
    assert result is not None, f"{trial.moment}: no end ({runner.state}, calls {trial.labels})"
    if trial.stop_thread is not None:
        trial.stop_thread.join(HANG_S)
    if runner._stopper is not None:  # a STOP after the end still halts the devices: let it
        runner._stopper.join(HANG_S)  # finish before the next trial uses them
    assert runner.state is MissionState.FINISHED, (trial.moment, result)
    missing = missing_keys(runner.plan, trial.writer)
    if result.outcome is Outcome.COMPLETE:
        assert missing == []
    else:
        assert result.outcome is Outcome.STOPPED, (trial.moment, result)
        assert result.fault is None
    assert runner._thread is not None  # a forced end: the late thread refreshes the status file
    runner._thread.join(HANG_S)
    status = json.loads((folder / STATUS_FILE).read_text())
    assert status["state"] == "finished" and status["outcome"] == result.outcome.value
    assert [tuple(key) for key in status["missing"]] == missing, trial.moment
    sim_table, sim_base = rig.rig.sim_table, rig.rig.sim_base
    assert sim_table is not None and sim_base is not None
    assert sim_table.state in ("Idle", "Hold:0"), (trial.moment, sim_table.state)
    base_state = sim_base.status().state
    assert base_state is not BaseState.MOVING, (trial.moment, base_state)
    if result.outcome is Outcome.STOPPED:  # the base obeyed STOP and stays latched
        assert base_state is BaseState.STOPPED, (trial.moment, trial.labels)
    report = verify_session(folder)
    assert report.usable, (trial.moment, report)  # a stop before the first capture too: a
    if not result.captured:  # well-formed session with nothing in it yet (the spec allows it)
        assert "no captures yet" in "\n".join(report.summary_lines()), report
    assert len(load_session(folder, allow_empty=True).captures) == result.captured
    return result.outcome.value


@pytest.mark.parametrize("seed", SEEDS)
def test_stop_at_random_moments_always_lands_stopped_and_consistent(
    seed: int, shared_rig: MissionSetup, tmp_path: Path
) -> None:
    plan = small_plan(stations=(5, 4), views=2, settle_s=0.02)
    outcomes: dict[str, int] = {}
    hows: set[str] = set()
    stopped_labels: set[str] = set()
    for number, moment in enumerate(moments(seed, TRIALS_PER_SEED)):
        folder = tmp_path / f"t{number:03d}"
        trial = Trial(shared_rig, plan, folder, moment)
        trial.runner.start()
        outcome = check_consistent(trial, folder, shared_rig)
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
        hows.add(moment.how)
        if moment.call <= len(trial.labels):
            stopped_labels.add(trial.labels[moment.call - 1])
    assert outcomes.get("stopped", 0) >= TRIALS_PER_SEED // 2, outcomes
    assert hows == {"before", "during", "pause", "resume"}
    # the STOPs fell on every kind of step: driving, turning, capturing, saving
    steps = ("base.follow_goal", "table.goto_deg", "gate.sleep", "camera.capture")
    for label in (*steps, "writer.add_capture"):
        assert label in stopped_labels, stopped_labels
