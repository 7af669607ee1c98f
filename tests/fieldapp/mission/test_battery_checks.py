"""The base's battery is checked before a mission starts and at every station: a warning below
the warning level, and at the critical level the current view is finished and saved, then the
mission stops saying to charge the battery."""

from __future__ import annotations

import json
import time
from collections.abc import Callable

import pytest

from fieldapp.io.session import load_session
from fieldapp.mission import MissionSetup, MissionState, MissionWarning, Outcome
from fieldapp.mission.folder import STATUS_FILE
from fieldapp.settings import BatterySettings

from .conftest import HANG_S, small_plan

Opener = Callable[..., MissionSetup]
LIMITS = BatterySettings(warn_pct=40.0, critical_pct=20.0)


def set_battery(setup: MissionSetup, level_pct: float) -> None:
    """Set the simulated battery and wait until the base reports it (its next update)."""
    assert setup.rig.sim_base is not None
    setup.rig.sim_base.model.battery_pct = level_pct
    for _ in range(1000):
        if abs(setup.rig.base.status().battery_pct - level_pct) < 1.0:
            return
        time.sleep(0.01)
    raise AssertionError("the base never reported the new level")


def test_a_mission_does_not_start_at_the_critical_level(open_mission: Opener) -> None:
    setup = open_mission(small_plan(stations=(5,), views=1))
    set_battery(setup, 19.0)
    result = setup.runner(LIMITS).start().wait(HANG_S)
    assert result is not None and result.outcome is Outcome.FAILED and result.captured == 0
    assert result.fault is not None and result.fault.device == "battery"
    assert "19 %" in result.fault.what and "before the mission started" in result.fault.what
    assert "charge" in result.fault.advice
    assert json.loads((setup.folder / STATUS_FILE).read_text())["state"] == "failed"


def test_a_low_battery_warns_once_per_station_and_the_mission_completes(
    open_mission: Opener,
) -> None:
    setup = open_mission(small_plan(stations=(5, 4), views=2))
    set_battery(setup, 35.0)
    runner = setup.runner(LIMITS)
    warnings: list[MissionWarning] = []
    runner.warning.connect(warnings.append)
    result = runner.start().wait(HANG_S)
    assert result is not None and result.complete
    battery = [w for w in warnings if w.text.startswith("battery low")]
    assert len(battery) == 3  # before the start, then once at each of the two stations
    assert [w.station for w in battery] == [None, 5, 4]


@pytest.mark.parametrize("after_view", [0, 1])
def test_at_the_critical_level_the_current_view_is_saved_then_the_mission_stops(
    open_mission: Opener, after_view: int
) -> None:
    setup = open_mission(small_plan(stations=(5, 4), views=2))
    set_battery(setup, 80.0)
    runner = setup.runner(LIMITS)
    runner.view_captured.connect(
        lambda e: set_battery(setup, 12.0) if (e.station, e.view) == (5, after_view) else None
    )
    result = runner.start().wait(HANG_S)
    assert result is not None and result.outcome is Outcome.FAILED
    assert runner.state is MissionState.FAILED
    assert result.captured == after_view + 1
    assert result.fault is not None and result.fault.device == "battery"
    assert f"after s5 v{after_view}" in result.fault.what
    saved = {(c.station, c.view) for c in load_session(setup.folder).captures}
    assert saved == {(5, v) for v in range(after_view + 1)}
    status = json.loads((setup.folder / STATUS_FILE).read_text())
    assert status["fault"]["device"] == "battery"
