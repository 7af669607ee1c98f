"""The runner on the simulated rig: captures as planned, writes as it goes, obeys the operator."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from fieldapp.io.calibration import load_calibration
from fieldapp.io.session import load_session
from fieldapp.mission import (
    MissionProgress,
    MissionSetup,
    MissionState,
    Outcome,
    StationReached,
    ViewCaptured,
    resume_mission,
)
from fieldapp.mission.folder import PLAN_FILE, STATUS_FILE
from fieldapp.mission.plan import ViewPlan, load_plan
from fieldapp.verify import verify_session

from .conftest import HANG_S, small_plan

Opener = Callable[..., MissionSetup]


def record(runner: Any) -> dict[str, list[Any]]:
    events: dict[str, list[Any]] = {"states": [], "stations": [], "views": [], "warnings": [],
                                    "progress": []}  # fmt: skip
    runner.state_changed.connect(events["states"].append)
    runner.station_reached.connect(events["stations"].append)
    runner.view_captured.connect(events["views"].append)
    runner.warning.connect(events["warnings"].append)
    runner.progress.connect(events["progress"].append)
    return events


def test_a_small_mission_captures_every_view_with_what_the_devices_reported(
    open_mission: Opener,
) -> None:
    plan = small_plan(stations=(5, 4), views=3)
    setup = open_mission(plan)
    runner = setup.runner()
    events = record(runner)
    result = runner.start().wait(HANG_S)
    assert result is not None and result.outcome is Outcome.COMPLETE, result
    assert runner.state is MissionState.FINISHED
    assert events["states"] == [MissionState.RUNNING, MissionState.FINISHED]
    assert result.missing == [] and result.captured == 6

    session = load_session(setup.folder)
    by_key = {(c.station, c.view): c for c in session.captures}
    assert sorted(by_key) == sorted(plan.capture_keys()) and len(session.captures) == 6
    reached: dict[int, StationReached] = {e.station: e for e in events["stations"]}
    assert sorted(reached) == [4, 5]
    for view_event in events["views"]:
        assert isinstance(view_event, ViewCaptured)
        capture = by_key[(view_event.station, view_event.view)]
        assert capture.angle_deg == pytest.approx(view_event.angle_deg, abs=1e-9)
        assert capture.angle_deg == pytest.approx(45.0 * view_event.view, abs=0.2)
        arrival = reached[view_event.station]
        assert capture.base_pose is not None
        assert (capture.base_pose.x, capture.base_pose.y, capture.base_pose.yaw_deg) == (
            pytest.approx(arrival.x_m),
            pytest.approx(arrival.y_m),
            pytest.approx(arrival.yaw_deg),
        )
        station = plan.station(view_event.station)
        assert np.hypot(arrival.x_m - station.x_m, arrival.y_m - station.y_m) < 0.05
        assert view_event.quality_ok and view_event.quality.fill_rate > 0.85
        assert view_event.thumbnail.dtype == np.uint8 and view_event.thumbnail.shape == (53, 64, 3)
    # views turn up at the first station and back down at the second
    assert [(e.station, e.view) for e in events["views"]] == [
        (5, 0), (5, 1), (5, 2), (4, 2), (4, 1), (4, 0)
    ]  # fmt: skip
    done = [p.done for p in events["progress"] if isinstance(p, MissionProgress)]
    assert done == [0, 1, 2, 3, 4, 5, 6]
    assert events["progress"][-1].remaining_s == pytest.approx(0.0)
    assert events["progress"][2].remaining_s > 0.0

    assert load_plan(setup.folder / PLAN_FILE) == plan
    calibration = load_calibration(setup.folder / "calibration.json")
    assert calibration.stations is not None and set(calibration.stations.to_reference) == {4, 5}
    status = json.loads((setup.folder / STATUS_FILE).read_text())
    assert status["state"] == "finished" and status["outcome"] == "complete"
    assert verify_session(setup.folder).usable


def test_pause_holds_at_a_step_boundary_and_resume_carries_on(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=3))
    runner = setup.runner()
    events = record(runner)
    paused = threading.Event()
    runner.view_captured.connect(lambda e: runner.pause() if e.view == 0 else None)
    runner.state_changed.connect(lambda s: paused.set() if s is MissionState.PAUSED else None)
    runner.start()
    assert paused.wait(HANG_S)
    time.sleep(0.3)
    assert runner.state is MissionState.PAUSED
    assert len(events["views"]) == 1 and len(load_session(setup.folder).captures) == 1
    runner.resume()
    result = runner.wait(HANG_S)
    assert result is not None and result.complete
    assert events["states"] == [
        MissionState.RUNNING, MissionState.PAUSED, MissionState.RUNNING, MissionState.FINISHED
    ]  # fmt: skip


def test_abort_ends_at_the_next_step_boundary_and_says_what_is_missing(
    open_mission: Opener,
) -> None:
    setup = open_mission(small_plan(stations=(5, 4), views=2))
    runner = setup.runner()
    events = record(runner)
    runner.view_captured.connect(lambda e: runner.abort())
    result = runner.start().wait(HANG_S)
    assert result is not None and result.outcome is Outcome.ABORTED and result.fault is None
    assert events["states"] == [
        MissionState.RUNNING, MissionState.STOPPING, MissionState.FINISHED
    ]  # fmt: skip
    assert result.captured == 1 and result.missing == [(5, 1), (4, 0), (4, 1)]
    status = json.loads((setup.folder / STATUS_FILE).read_text())
    assert status["outcome"] == "aborted" and status["missing"] == [[5, 1], [4, 0], [4, 1]]
    assert setup.rig.sim_base is not None and not setup.rig.sim_base.latched


def test_stop_holds_the_table_mid_move_and_stops_the_base_then_resume_completes(
    open_mission: Opener,
) -> None:
    plan = small_plan(stations=(5,), views=ViewPlan(count=2, step_deg=20.0))
    setup = open_mission(plan, realtime=True)
    assert setup.rig.sim_base is not None
    setup.rig.sim_base.backend.time_scale = 1000.0  # the table turns in real time, not the base
    runner = setup.runner()
    first = threading.Event()
    runner.view_captured.connect(lambda e: first.set())
    runner.start()
    assert first.wait(HANG_S)
    sim_table = setup.rig.sim_table
    assert sim_table is not None
    deadline_s = time.monotonic() + HANG_S
    while not sim_table.state.startswith("Run"):  # the table turns towards view 1 (20 deg)
        assert time.monotonic() < deadline_s, sim_table.state
        time.sleep(0.01)
    runner.stop()
    result = runner.wait(HANG_S)
    assert result is not None and result.outcome is Outcome.STOPPED, result
    assert runner.state is MissionState.FINISHED and result.missing == [(5, 1)]
    assert sim_table.state == "Hold:0" and 0.0 < sim_table.angle_deg < 20.0
    assert setup.rig.sim_base is not None and setup.rig.sim_base.latched

    again = setup.runner()
    warnings = record(again)["warnings"]
    result = again.start().wait(HANG_S)
    assert result is not None and result.complete, result
    texts = " ".join(w.text for w in warnings)
    assert "stop latch was set" in texts and "table was held" in texts
    captures = load_session(setup.folder).captures
    assert sorted((c.station, c.view) for c in captures) == [(5, 0), (5, 1)]


def test_resume_of_a_folder_captures_only_what_is_missing(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5, 4), views=2))
    runner = setup.runner()
    runner.view_captured.connect(lambda e: runner.abort() if e.station == 4 else None)
    first = runner.start().wait(HANG_S)
    assert first is not None and first.missing == [(4, 0)]  # station 4 turns back: 1, then 0
    setup.close()
    before = {(c.station, c.view): c.captured_at for c in load_session(setup.folder).captures}
    with resume_mission(setup.folder, realtime=False, world=setup.rig.world) as resumed:
        assert resumed.missing() == [(4, 0)]
        again = resumed.runner()
        views = record(again)["views"]
        result = again.start().wait(HANG_S)
    assert result is not None and result.complete
    assert [(e.station, e.view) for e in views] == [(4, 0)]
    after = {(c.station, c.view): c.captured_at for c in load_session(setup.folder).captures}
    assert len(after) == 4 and all(after[key] == value for key, value in before.items())


def test_the_table_is_parked_at_its_machine_zero_after_the_last_view(
    open_mission: Opener,
) -> None:
    """A board reset by the next opening of its port (DTR) starts with its machine position
    at 0 where the table stands (gnea/grbl main.c): left at 90 degrees, the next mission's
    views would all be 90 degrees off. The table is turned back after the last view."""
    setup = open_mission(small_plan(stations=(5,), views=3))
    runner = setup.runner()
    events = record(runner)
    result = runner.start().wait(HANG_S)
    assert result is not None and result.outcome is Outcome.COMPLETE, result
    assert [e.angle_deg for e in events["views"]] == pytest.approx([0.0, 45.0, 90.0], abs=0.2)
    assert setup.rig.sim_table.angle_deg == pytest.approx(0.0, abs=0.2)
    assert events["warnings"] == []
