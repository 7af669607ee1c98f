"""Issue 23, findings 5 and 8: after a lost link (or a blocked path) the mission recovers only
by the operator's choice or an explicit policy, and the policy is recorded in the session."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from devices.base import SimFault, open_base
from devices.base.protocol import BaseState, Command, Pose
from fieldapp.cli.mission import _with_incident_policy, register
from fieldapp.mission import MissionResult, MissionSetup
from fieldapp.mission.folder import read_plan
from fieldapp.mission.incidents import Choice, Incident, IncidentKind
from fieldapp.mission.plan import RetryLimits, default_plan, grid_stations
from fieldapp.settings import IncidentPolicy

from .conftest import HANG_S, small_plan

Opener = Callable[..., MissionSetup]


def _run(
    setup: MissionSetup,
    prompt: Callable[[Incident], Choice] | None = None,
    link_comes_back: bool = True,
) -> tuple[MissionResult, list[str]]:
    """Run with the base frozen (a lost link) from the start; it comes back at the first
    warning unless ``link_comes_back`` is False."""
    base = setup.rig.sim_base
    assert base is not None
    runner = setup.runner()
    runner.gate.operator_prompt = prompt
    runner.progress.connect(
        lambda p: base.inject_fault(SimFault.FREEZE) if p.step == "starting" else None
    )
    warnings: list[str] = []
    runner.warning.connect(lambda w: warnings.append(w.text))
    if link_comes_back:
        runner.warning.connect(lambda w: base.clear_faults())
    result = runner.start().wait(120)
    assert result is not None
    return result, warnings


def test_a_lost_link_stops_the_mission_when_nobody_decides(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    assert setup.plan.incidents.lost_link == "ask"  # the default: the operator decides
    result, warnings = _run(setup)  # no prompt (a terminal): ask means stop
    assert result.fault is not None and "link lost" in result.fault.what
    assert warnings == []  # no retry by itself
    assert setup.rig.sim_base is not None
    assert setup.rig.sim_base.executed[Command.RESET] == 0  # the latch was not cleared


def test_the_operator_is_asked_and_resumes(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    base = setup.rig.sim_base
    assert base is not None
    asked: list[Incident] = []

    def operator(incident: Incident) -> Choice:
        asked.append(incident)
        base.clear_faults()  # the operator fixed the Wi-Fi
        return Choice.RESUME

    result, warnings = _run(setup, operator)
    assert result.complete, result
    assert [(i.kind, i.station) for i in asked] == [(IncidentKind.LOST_LINK, 5)]
    assert Choice.SKIP_STATION in asked[0].choices
    assert any("resuming" in w for w in warnings)


def test_the_operator_can_skip_a_station(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(4, 5), views=1))
    base = setup.rig.sim_base
    assert base is not None

    def operator(incident: Incident) -> Choice:
        base.clear_faults()
        return Choice.SKIP_STATION

    result, warnings = _run(setup, operator)
    assert result.captured == 1 and result.missing == [(4, 0)]  # station 5 was captured
    assert any("station 4 skipped" in w for w in warnings)


def test_a_resume_policy_recovers_by_itself_and_is_recorded(open_mission: Opener) -> None:
    plan = small_plan(stations=(5,), views=1, incidents=IncidentPolicy(lost_link="resume"))
    setup = open_mission(plan)
    base = setup.rig.sim_base
    assert base is not None
    runner = setup.runner()
    runner.progress.connect(
        lambda p: base.inject_fault(SimFault.FREEZE) if p.step == "starting" else None
    )
    runner.warning.connect(lambda w: base.clear_faults())
    result = runner.start().wait(120)
    assert result is not None and result.complete
    assert read_plan(setup.folder).incidents.lost_link == "resume"


def test_a_resume_policy_gives_up_after_the_retries(open_mission: Opener) -> None:
    plan = small_plan(
        stations=(5,),
        views=1,
        retries=RetryLimits(navigation=1, base_link_wait_s=0.1),
        incidents=IncidentPolicy(lost_link="resume"),
    )
    result, warnings = _run(open_mission(plan), link_comes_back=False)
    assert result.fault is not None and "link lost" in result.fault.what
    assert sum("resuming" in w for w in warnings) == 1


def test_a_blocked_path_can_be_skipped_by_policy(open_mission: Opener) -> None:
    plan = small_plan(
        stations=(4, 5),
        views=1,
        retries=RetryLimits(navigation=0, base_link_wait_s=0.1),
        incidents=IncidentPolicy(blocked_path="skip"),
    )
    setup = open_mission(plan)
    base = setup.rig.sim_base
    assert base is not None
    base.inject_fault(SimFault.BLOCKED_PATH)
    runner = setup.runner()
    runner.warning.connect(lambda w: base.clear_faults())
    result = runner.start().wait(120)
    assert result is not None
    assert result.missing == [(4, 0)] and result.captured == 1


def _cli(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    return parser.parse_args(["mission", "run", "--out", "S", *argv])


def test_the_command_line_resumes_only_when_told() -> None:
    plan = default_plan()
    assert _with_incident_policy(plan, _cli()).incidents.lost_link == "stop"
    told = _with_incident_policy(
        plan, _cli("--on-lost-link", "resume", "--on-blocked-path", "skip")
    )
    assert (told.incidents.lost_link, told.incidents.blocked_path) == ("resume", "skip")


def test_a_goal_the_link_lost_that_reaches_the_base_late_is_superseded(
    open_mission: Opener,
) -> None:
    """A station's request whose replies the link lost reached the base after all, after the
    mission had given that station up and found the base at rest: the base is on its way
    there when the next station's goal comes, and refuses it as busy. The late goal is this
    client's own, so it is cancelled and the station's goal sent again; another client's goal
    would be left alone (``test_command_semantics``)."""
    setup = open_mission(small_plan(stations=(5,), views=1), realtime=True)
    sim = setup.rig.sim_base
    assert sim is not None
    far = next(s for s in grid_stations() if s.number == 1)  # 2.3 m away: seconds of driving
    setup.rig.base.goto("s04-late", Pose(far.x_m, far.y_m, far.yaw_deg), wait=False)
    assert setup.rig.base.sent_goal("s04-late") and not setup.rig.base.sent_goal("s05")
    result = setup.runner().start().wait(HANG_S)
    assert result is not None and result.complete, result
    assert sim.executed[Command.CANCEL] == 1
    assert sim.status().state is BaseState.ARRIVED and sim.status().goal_id != "s04-late"


def test_another_client_s_goal_is_not_cancelled_by_the_mission(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1), realtime=True)
    sim = setup.rig.sim_base
    assert sim is not None
    other = open_base(sim.command_endpoint, None)
    try:
        far = next(s for s in grid_stations() if s.number == 1)
        other.goto("teleop", Pose(far.x_m, far.y_m, far.yaw_deg), wait=False)
        result = setup.runner().start().wait(HANG_S)
        assert result is not None and result.fault is not None, result
        assert "busy" in result.fault.what
        assert sim.executed[Command.CANCEL] == 0
    finally:
        other.close()
