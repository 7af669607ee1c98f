"""The real driver against the simulated controller over a real pseudo-terminal."""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Callable

import pytest
import serial

from devices.table import (
    GrblSimulator,
    GrblTable,
    PtyGrblServer,
    TableAlarm,
    TableDisconnected,
    TableError,
    TableHeld,
    TableMissedTarget,
    TableReset,
    TableTimeouts,
    open_table,
)

from ..fake_clock import FakeClock, wait_real
from .conftest import FAST, QUICK_TABLE, goto_in_background

MakeServer = Callable[..., PtyGrblServer]
MakeTable = Callable[..., GrblTable]


def test_connect_reads_banner_status_and_settings(server: PtyGrblServer) -> None:
    table = open_table(server.device_path, timeouts=FAST)
    try:
        assert server.simulator.soft_resets_received == 0  # the banner came: no Ctrl-X needed
        status = table.status()
        assert (status.state, status.position_deg, status.position_known) == ("Idle", 0.0, True)
        assert table.settings[100] == 1600.0
        assert table.settings[110] == 720.0
    finally:
        table.close()


def test_connect_without_banner_sends_ctrl_x(make_server: MakeServer) -> None:
    quiet = make_server(GrblSimulator(), reset_on_open=False)
    timeouts = TableTimeouts(banner_s=0.3, reply_s=0.5, status_s=0.2)
    clock = FakeClock()
    port = serial.serial_for_url(quiet.device_path, baudrate=115200, timeout=0.05)
    table = GrblTable(port, timeouts=timeouts, clock=clock)
    connecting = threading.Thread(target=table.connect, daemon=True)
    try:
        connecting.start()
        assert wait_real(lambda: clock.reads > 0)  # waiting for the banner
        clock.advance(timeouts.banner_s - 0.01)
        time.sleep(0.2)
        assert quiet.simulator.soft_resets_received == 0  # not before the banner's bound
        clock.advance(0.02)
        assert wait_real(lambda: quiet.simulator.soft_resets_received == 1)
        connecting.join(timeout=20.0)
        assert not connecting.is_alive()
        assert table.status().state == "Idle"
    finally:
        table.close()


@pytest.mark.parametrize("targets", [[45.0, 90.0, 135.0, 0.0], [-12.25, 370.5, 0.125]])
def test_goto_reaches_each_target(
    server: PtyGrblServer, table: GrblTable, targets: list[float]
) -> None:
    for target_deg in targets:
        assert table.goto_deg(target_deg) == pytest.approx(target_deg, abs=5e-4)
        assert server.simulator.angle_deg == pytest.approx(target_deg, abs=1e-6)
        assert table.position_deg() == pytest.approx(target_deg, abs=5e-4)
    lines = list(server.simulator.executed_lines)
    assert lines[-2:] == [f"G21G90G0X{targets[-1]:.4f}", "G4P0"]


def test_goto_in_real_time_waits_for_the_move(
    timed_server: PtyGrblServer, make_table: MakeTable
) -> None:
    table = make_table(timed_server)
    seen: list[float] = []
    table.position_deg_changed.connect(seen.append)
    started_s = time.monotonic()
    assert table.goto_deg(20.0) == pytest.approx(20.0, abs=5e-4)
    elapsed_s = time.monotonic() - started_s
    travel_s = 20.0 / 30.0 + 30.0 / 60.0  # trapezoid: cruise + accelerate/brake
    assert elapsed_s >= travel_s - 0.05  # the barrier waited for the physics (never faster)
    assert any(0.0 < deg < 20.0 for deg in seen)  # positions polled during the move


def test_stops_a_little_off_target_within_tolerance(
    make_server: MakeServer, make_table: MakeTable
) -> None:
    server = make_server(GrblSimulator(off_target_deg=0.05, seed=11))
    table = make_table(server)
    expected = random.Random(11).uniform(-0.05, 0.05)
    reached = table.goto_deg(30.0)
    assert reached == pytest.approx(30.0 + expected, abs=5e-4)
    assert reached != 30.0


def test_beyond_tolerance_is_not_done(make_server: MakeServer, make_table: MakeTable) -> None:
    server = make_server(GrblSimulator(off_target_deg=0.5, seed=0))
    table = make_table(server)
    offset = random.Random(0).uniform(-0.5, 0.5)
    assert abs(offset) > 0.2
    with pytest.raises(TableMissedTarget) as caught:
        table.goto_deg(30.0)
    assert caught.value.reached_deg == pytest.approx(30.0 + offset, abs=5e-4)


def test_error_reply_is_a_typed_error(table: GrblTable) -> None:
    with pytest.raises(TableError) as caught:
        table.home()  # homing disabled ($22=0) on this controller
    assert caught.value.code == 5
    assert "homing" in str(caught.value)
    assert table.goto_deg(5.0) == pytest.approx(5.0)  # still in step


def test_hold_stops_the_move_and_resume_finishes_it(
    timed_server: PtyGrblServer, make_table: MakeTable
) -> None:
    table = make_table(timed_server)
    mover, outcome = goto_in_background(table, 20.0)
    time.sleep(0.4)
    held = table.hold()
    mover.join(timeout=5.0)
    assert isinstance(outcome[0], TableHeld)
    assert (held.state, held.substate) == ("Hold", 0)
    assert 0.0 < held.position_deg < 20.0
    with pytest.raises(TableHeld):
        table.goto_deg(20.0)
    table.resume()
    assert table.goto_deg(20.0) == pytest.approx(20.0)  # the stale G4 answer is resynced


def test_reset_mid_move_marks_the_position_unknown(
    timed_server: PtyGrblServer, make_table: MakeTable
) -> None:
    table = make_table(timed_server)
    reasons: list[str] = []
    table.position_unknown.connect(reasons.append)
    mover, outcome = goto_in_background(table, 20.0)
    time.sleep(0.4)
    status = table.reset()
    mover.join(timeout=5.0)
    assert isinstance(outcome[0], TableReset)
    assert (status.state, status.alarm_code, status.position_known) == ("Alarm", 3, False)
    assert reasons
    with pytest.raises(TableAlarm, match="ALARM:3"):
        table.goto_deg(0.0)


def test_home_and_unlock_only_when_asked(make_server: MakeServer, make_table: MakeTable) -> None:
    server = make_server(GrblSimulator(settings={22: 1}))
    table = make_table(server)
    assert table.status().state == "Alarm"
    assert not table.position_known
    with pytest.raises(TableAlarm, match="unlock"):
        table.goto_deg(10.0)
    assert not {"$X", "$H"} & set(server.simulator.executed_lines)
    assert table.home() == 0.0
    assert table.position_known
    assert table.goto_deg(10.0) == pytest.approx(10.0)


def test_open_table_on_a_missing_port() -> None:
    with pytest.raises(TableDisconnected, match="/dev/does-not-exist"):
        open_table("/dev/does-not-exist", timeouts=FAST)


assert QUICK_TABLE[110] == 1800.0  # the timings above assume 30 deg/s and 60 deg/s^2
