"""Injected faults end in the stated behaviour: a bounded retry where safe, otherwise a clean
stop that marks what is missing and says what happened and what to do."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from devices.base import SimFault
from devices.camera import CameraTimeout, DepthCamera, Frame
from fieldapp.io.session import load_session
from fieldapp.mission import MissionResult, MissionSetup, MissionState, Outcome
from fieldapp.mission.folder import STATUS_FILE
from fieldapp.mission.plan import RetryLimits
from fieldapp.settings import CameraQualitySettings, IncidentPolicy

from .conftest import HANG_S, WrappedCamera, small_plan

Opener = Callable[..., MissionSetup]


class FaultyCamera(WrappedCamera):
    """Wraps a camera: the first ``timeouts`` reads time out, the next ``covered`` captures see
    nothing (a covered lens: no depth at all)."""

    def __init__(self, inner: DepthCamera, timeouts: int = 0, covered: int = 0) -> None:
        super().__init__(inner)
        self.timeouts, self.covered = timeouts, covered

    def _read(self, timeout_s: float) -> Frame:
        if self.timeouts > 0:
            self.timeouts -= 1
            raise CameraTimeout(f"no frame within {timeout_s:.1f} s")
        frame = self.inner.read_frame(timeout_s)
        if self.covered > 0:
            self.covered -= 1
            frame.depth_m = np.full_like(frame.depth_m, np.nan)
        return frame


def run(
    setup: MissionSetup,
    on_warning: Callable[[Any], None] | None = None,
    on_start: Callable[[], None] | None = None,
) -> tuple[MissionResult, list[str]]:
    """Run the mission; ``on_start`` is called once the devices are ready (first progress)."""
    runner = setup.runner()
    if on_start is not None:
        runner.progress.connect(lambda p: on_start() if p.step == "starting" else None)
    warnings: list[str] = []
    runner.warning.connect(lambda w: warnings.append(w.text))
    if on_warning is not None:
        runner.warning.connect(on_warning)
    result = runner.start().wait(HANG_S)
    assert result is not None
    assert runner.state is (MissionState.FAILED if result.outcome is Outcome.FAILED
                            else MissionState.FINISHED)  # fmt: skip
    return result, warnings


def assert_stopped_cleanly(setup: MissionSetup, result: MissionResult, device: str) -> None:
    """Failed with a fault naming the device and advice; the folder lists only complete
    captures, and its status file says what is missing and what to do."""
    assert result.outcome is Outcome.FAILED and result.fault is not None
    assert result.fault.device == device and "resume" in result.fault.advice
    captures = load_session(setup.folder, allow_empty=True).captures
    present = {(c.station, c.view) for c in captures}
    assert len(present) == len(captures) == result.captured
    assert result.missing == [k for k in setup.plan.capture_keys() if k not in present]
    status = json.loads((setup.folder / STATUS_FILE).read_text())
    assert status["state"] == "failed" and status["missing"] == [list(k) for k in result.missing]
    assert status["fault"]["advice"] == result.fault.advice


def test_navigation_failure_is_retried_then_the_mission_completes(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    assert setup.rig.sim_base is not None
    base = setup.rig.sim_base
    base.inject_fault(SimFault.NAV_FAILURE)
    result, warnings = run(setup, on_warning=lambda w: base.clear_faults())
    assert result.complete
    assert (len(warnings) == 1 and "navigation failed" in warnings[0]) or "aborted" in warnings[0]


def test_navigation_failing_every_time_stops_the_mission(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5, 4), views=1, retries=RetryLimits(navigation=1)))
    assert setup.rig.sim_base is not None
    setup.rig.sim_base.inject_fault(SimFault.BLOCKED_PATH)
    result, warnings = run(setup)
    assert_stopped_cleanly(setup, result, "base")
    assert result.captured == 0 and len(warnings) == 1  # one retry, then the stop
    assert result.fault is not None and "path blocked" in result.fault.what
    assert "clear the path" in result.fault.advice


def test_a_base_link_that_comes_back_is_retried(open_mission: Opener) -> None:
    policy = IncidentPolicy(lost_link="resume")  # by itself only when the plan says so
    setup = open_mission(small_plan(stations=(5,), views=1, incidents=policy))
    base = setup.rig.sim_base
    assert base is not None
    result, warnings = run(
        setup,
        on_warning=lambda w: base.clear_faults(),
        on_start=lambda: base.inject_fault(SimFault.FREEZE),
    )
    assert result.complete, result
    assert any("link lost" in w for w in warnings)


def test_a_base_link_lost_for_good_stops_the_mission(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1, retries=RetryLimits(
        navigation=1, base_link_wait_s=0.1)))  # fmt: skip
    base = setup.rig.sim_base
    assert base is not None
    result, _ = run(setup, on_start=lambda: base.inject_fault(SimFault.FREEZE))
    assert_stopped_cleanly(setup, result, "base")
    assert result.fault is not None and "link lost" in result.fault.what
    assert "Wi-Fi" in result.fault.advice and "watchdog" in result.fault.advice


def test_a_table_alarm_is_left_to_the_operator(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=2))
    assert setup.rig.sim_table is not None
    setup.rig.sim_table.inject_stall(after_deg=10.0)  # on the way to view 1 (45 deg)
    result, warnings = run(setup)
    assert_stopped_cleanly(setup, result, "table")
    assert result.missing == [(5, 1)] and warnings == []  # no retry: the table is in alarm
    assert result.fault is not None and "ALARM:1" in result.fault.what
    assert "unlock" in result.fault.advice
    assert setup.rig.sim_table.angle_deg == pytest.approx(10.0, abs=0.5)  # stalled, not moved


def test_an_unplugged_table_stops_the_mission(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=2))
    assert setup.rig.table_server is not None
    server = setup.rig.table_server
    runner_result, _ = run_with_unplug(setup, server)
    assert_stopped_cleanly(setup, runner_result, "table")
    assert runner_result.missing == [(5, 1)]
    assert runner_result.fault is not None and "disconnected" in runner_result.fault.what
    assert "USB cable" in runner_result.fault.advice


def run_with_unplug(setup: MissionSetup, server: Any) -> tuple[MissionResult, list[str]]:
    runner = setup.runner()
    runner.view_captured.connect(lambda e: server.unplug())
    result = runner.start().wait(HANG_S)
    assert result is not None
    return result, []


def test_camera_timeouts_are_retried(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    setup.rig.camera = FaultyCamera(setup.rig.camera, timeouts=2)
    result, warnings = run(setup)
    assert result.complete
    assert len(warnings) == 2 and all("no frame within" in w for w in warnings)


def test_a_camera_that_keeps_timing_out_stops_the_mission(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    setup.rig.camera = FaultyCamera(setup.rig.camera, timeouts=100)
    result, warnings = run(setup)
    assert_stopped_cleanly(setup, result, "camera")
    assert len(warnings) == setup.plan.retries.camera
    assert result.fault is not None and "USB 3 cable" in result.fault.advice


def test_a_capture_below_quality_is_taken_again(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    setup.rig.camera = FaultyCamera(setup.rig.camera, covered=1)
    runner = setup.runner()
    views: list[Any] = []
    runner.view_captured.connect(views.append)
    warnings: list[str] = []
    runner.warning.connect(lambda w: warnings.append(w.text))
    result = runner.start().wait(HANG_S)
    assert result is not None and result.complete
    assert len(warnings) == 1 and "below quality" in warnings[0] and "crop region" in warnings[0]
    assert views[0].quality_ok and views[0].attempts == 2


def test_a_view_that_stays_below_quality_stops_the_mission_or_is_kept_when_planned(
    open_mission: Opener,
) -> None:
    impossible = CameraQualitySettings(min_fill_rate=1.0)
    setup = open_mission(small_plan(stations=(5,), views=1, quality=impossible))
    result, warnings = run(setup)
    assert_stopped_cleanly(setup, result, "camera")
    assert len(warnings) == setup.plan.retries.quality
    assert result.fault is not None and "depth fill rate" in result.fault.what
    assert "clean the lens" in result.fault.advice
    setup.close()


def test_keep_low_quality_keeps_the_best_attempt_with_a_warning(open_mission: Opener) -> None:
    impossible = CameraQualitySettings(min_fill_rate=1.0)
    plan = small_plan(stations=(5,), views=1, quality=impossible, keep_low_quality=True)
    setup = open_mission(plan)
    result, warnings = run(setup)
    assert result.complete
    assert "kept below quality" in warnings[-1]
    capture = load_session(setup.folder).captures[0]
    assert (
        capture.model_extra is not None and 0.85 < capture.model_extra["quality"]["fill_rate"] < 1.0
    )


def test_a_base_offline_from_the_start_says_link_lost(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    assert setup.rig.sim_base is not None
    setup.rig.sim_base.inject_fault(SimFault.FREEZE)
    result, _ = run(setup)
    assert_stopped_cleanly(setup, result, "base")
    assert result.fault is not None and "link lost" in result.fault.what


def test_a_base_link_closed_by_the_application_is_named_as_such(open_mission: Opener) -> None:
    """The application closing the base's link under a running mission (it is quitting) ends
    the waiting request at once: the fault says the link was closed, not that the plan's
    poses are wrong or the Wi-Fi is down."""
    setup = open_mission(small_plan(stations=(5,), views=1))
    result, _ = run(setup, on_start=setup.rig.base.close)
    assert_stopped_cleanly(setup, result, "base")
    assert result.fault is not None and "was closed" in result.fault.what
    assert "open the base's link again" in result.fault.advice
