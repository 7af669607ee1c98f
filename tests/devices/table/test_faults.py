"""Each injected fault, through the real driver over a real pty: typed errors, never a hang,
never a false "done"."""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from devices.table import (
    GrblSimulator,
    GrblTable,
    PtyGrblServer,
    TableAlarm,
    TableDisconnected,
    TableTimeout,
    TableTimeouts,
)

from .conftest import FAST, goto_in_background

MakeServer = Callable[..., PtyGrblServer]
MakeTable = Callable[..., GrblTable]


def test_stall_during_a_move_blocks_moves_until_the_operator_acts(
    server: PtyGrblServer, table: GrblTable
) -> None:
    alarms: list[tuple[int, str]] = []
    table.alarm_raised.connect(lambda code, meaning: alarms.append((code, meaning)))
    server.simulator.inject_stall(after_deg=12.0)
    with pytest.raises(TableAlarm, match="ALARM:1") as caught:
        table.goto_deg(90.0)
    assert caught.value.code == 1
    assert alarms and alarms[0][0] == 1  # the operator is told
    assert not table.position_known
    sent = len(server.simulator.executed_lines)
    with pytest.raises(TableAlarm, match="moves refused"):
        table.goto_deg(45.0)
    with pytest.raises(TableAlarm, match="reset"):
        table.unlock()  # a hard limit needs a reset first
    assert len(server.simulator.executed_lines) == sent  # nothing was sent to the controller
    assert "$X" not in server.simulator.executed_lines
    assert table.reset().state == "Alarm"
    assert table.unlock().state == "Idle"
    assert server.simulator.executed_lines[-1] == "$X"
    assert table.goto_deg(45.0) == pytest.approx(45.0)
    assert not table.position_known  # unlocking does not make the position known


def test_alarm_in_the_middle_of_a_real_time_move(
    timed_server: PtyGrblServer, make_table: MakeTable
) -> None:
    table = make_table(timed_server)
    mover, outcome = goto_in_background(table, 20.0)
    time.sleep(0.4)
    timed_server.simulator.inject_alarm(2)
    mover.join(timeout=5.0)
    assert isinstance(outcome[0], TableAlarm)
    assert outcome[0].code == 2
    assert 0.0 < timed_server.simulator.angle_deg < 20.0
    with pytest.raises(TableAlarm):
        table.goto_deg(20.0)


def test_lost_alarm_line_is_still_seen_through_the_status(
    server: PtyGrblServer, make_table: MakeTable
) -> None:
    table = make_table(server)
    server.simulator.inject_stall(after_deg=3.0)
    server.simulator.garble(count=1, skip=2)  # status, ok of G0, then ALARM:1 garbled
    started_s = time.monotonic()
    with pytest.raises(TableAlarm):
        table.goto_deg(90.0)
    assert time.monotonic() - started_s < 1.0  # found by polling, not by timing out


def test_no_reply_times_out_within_the_bound(server: PtyGrblServer, table: GrblTable) -> None:
    server.simulator.set_silent(True)
    for call in (table.status, lambda: table.goto_deg(10.0)):
        started_s = time.monotonic()
        with pytest.raises(TableTimeout):
            call()
        assert time.monotonic() - started_s <= 3 * FAST.status_s + 0.3
    assert server.simulator.angle_deg == 0.0


def test_silence_during_a_move_times_out_within_the_move_bound(
    timed_server: PtyGrblServer, make_table: MakeTable
) -> None:
    table = make_table(timed_server)
    started_s = time.monotonic()
    mover, outcome = goto_in_background(table, 20.0)
    time.sleep(0.2)
    timed_server.simulator.set_silent(True)
    mover.join(timeout=10.0)
    elapsed_s = time.monotonic() - started_s
    bound_s = 1.5 * (20.0 / 30.0 + 30.0 / 60.0) + FAST.move_margin_s
    assert isinstance(outcome[0], TableTimeout)
    assert bound_s - 0.1 <= elapsed_s <= bound_s + 0.5


def test_garbled_barrier_answer_is_no_false_done(
    make_server: MakeServer, make_table: MakeTable
) -> None:
    server = make_server(GrblSimulator(seed=5))
    table = make_table(server, TableTimeouts(**{**FAST.__dict__, "poll_s": 5.0}))
    server.simulator.garble(count=1, skip=2)  # status, ok of G0, then the ok of G4 P0
    with pytest.raises(TableTimeout):
        table.goto_deg(5.0)
    assert server.simulator.angle_deg == pytest.approx(5.0)  # it moved, but we cannot know
    assert table.goto_deg(8.0) == pytest.approx(8.0)  # back in step after a resync
    assert "$G" in server.simulator.executed_lines


def test_garbled_status_is_asked_again(server: PtyGrblServer, table: GrblTable) -> None:
    server.simulator.garble(count=1, skip=3)  # status, ok, ok, then the final status
    assert table.goto_deg(30.0) == pytest.approx(30.0)


def test_garbled_noise_between_answers_keeps_the_accounting(
    server: PtyGrblServer, table: GrblTable
) -> None:
    for target_deg in (10.0, 20.0, 30.0):
        server.simulator.garble(count=1, skip=1)  # the ok of the move line is lost
        with pytest.raises(TableTimeout):
            table.goto_deg(target_deg)
        assert table.goto_deg(target_deg + 1.0) == pytest.approx(target_deg + 1.0)


def test_unplug_mid_move(timed_server: PtyGrblServer, make_table: MakeTable) -> None:
    table = make_table(timed_server)
    reasons: list[str] = []
    table.disconnected.connect(reasons.append)
    assert table.position_known
    mover, outcome = goto_in_background(table, 20.0)
    time.sleep(0.4)
    timed_server.unplug()
    mover.join(timeout=5.0)
    assert isinstance(outcome[0], TableDisconnected)
    assert reasons
    assert not table.position_known
    with pytest.raises(TableDisconnected):
        table.status()
