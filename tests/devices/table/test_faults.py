"""Each injected fault, through the real driver over a real pty: typed errors, never a hang,
never a false "done"."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from devices.table import (
    GrblSimulator,
    GrblTable,
    PtyGrblServer,
    TableAlarm,
    TableDisconnected,
    TableHeld,
    TableMisconfigured,
    TablePositionUnknown,
    TableStatus,
    TableTimeout,
    TableTimeouts,
    open_table,
)
from devices.table.link import GrblLink
from devices.table.protocol import BARRIER_LINE

from ..fake_clock import FakeClock, wait_real
from .conftest import FAST, QUICK_TABLE, advance_while_polling, goto_in_background

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
    assert not table.position_known  # unlocking does not make the position known
    sent = len(server.simulator.executed_lines)
    with pytest.raises(TablePositionUnknown, match="home the table or confirm"):
        table.goto_deg(45.0)
    assert len(server.simulator.executed_lines) == sent  # refused: nothing sent
    table.confirm_position_known()  # the operator checked the zero mark
    assert table.goto_deg(45.0) == pytest.approx(45.0)


def _in_background(call: Callable[[], object]) -> tuple[threading.Thread, list[BaseException]]:
    outcome: list[BaseException] = []

    def run() -> None:
        try:
            call()
        except BaseException as error:
            outcome.append(error)

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    return worker, outcome


def test_alarm_in_the_middle_of_a_real_time_move(
    timed_server: PtyGrblServer, make_table: MakeTable
) -> None:
    table = make_table(timed_server)
    mover, outcome = goto_in_background(table, 20.0)
    time.sleep(0.4)
    timed_server.simulator.inject_alarm(2)
    mover.join(timeout=20.0)
    assert isinstance(outcome[0], TableAlarm)
    assert outcome[0].code == 2
    assert 0.0 < timed_server.simulator.angle_deg < 20.0
    with pytest.raises(TableAlarm):
        table.goto_deg(20.0)


def test_lost_alarm_line_is_still_seen_through_the_status(
    server: PtyGrblServer, make_table: MakeTable
) -> None:
    clock = FakeClock()
    table = make_table(server, clock=clock)
    server.simulator.inject_stall(after_deg=3.0)
    server.simulator.garble(count=1, skip=2)  # status, ok of G0, then ALARM:1 garbled
    lines = len(server.simulator.executed_lines)
    mover, outcome = goto_in_background(table, 90.0)
    assert wait_real(lambda: len(server.simulator.executed_lines) > lines)  # the move ran
    took_s = advance_while_polling(table, clock, mover, FAST.poll_s, FAST.move_max_s)
    assert isinstance(outcome[0], TableAlarm)
    assert took_s <= 3 * FAST.poll_s  # found by polling, not by timing out


def test_no_reply_times_out_at_the_bound(server: PtyGrblServer, make_table: MakeTable) -> None:
    clock = FakeClock()
    table = make_table(server, clock=clock)
    server.simulator.set_silent(True)
    for call in (table.status, lambda: table.goto_deg(10.0)):
        reads = clock.reads
        worker, outcome = _in_background(call)
        assert wait_real(lambda reads=reads: clock.reads > reads)  # its deadline is set
        clock.advance(3 * FAST.status_s - 0.01)  # three unanswered queries share one deadline
        time.sleep(0.2)
        assert worker.is_alive()
        clock.advance(0.02)
        worker.join(timeout=20.0)
        assert isinstance(outcome[0], TableTimeout)
    assert server.simulator.angle_deg == 0.0


def test_silence_during_a_move_is_reported_within_the_failure_budget(
    timed_server: PtyGrblServer, make_table: MakeTable
) -> None:
    clock = FakeClock()
    table = make_table(timed_server, clock=clock)
    mover, outcome = goto_in_background(table, 90.0)  # 3.5 s of travel: bound 5.75 s
    barrier = BARRIER_LINE.replace(" ", "")
    assert wait_real(lambda: barrier in timed_server.simulator.executed_lines)
    timed_server.simulator.set_silent(True)
    polls_answered = table.statuses_received
    clock.advance(FAST.failure_s - 0.01)  # not silent for the whole budget yet
    time.sleep(0.2)
    assert mover.is_alive()
    assert table.statuses_received == polls_answered
    clock.advance(0.02)
    mover.join(timeout=20.0)
    assert isinstance(outcome[0], TableTimeout)
    assert "silent" in str(outcome[0])


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
    mover.join(timeout=20.0)
    assert isinstance(outcome[0], TableDisconnected)
    assert reasons
    assert not table.position_known
    with pytest.raises(TableDisconnected):
        table.status()


def test_a_homing_cycle_longer_than_the_failure_budget_is_no_silent_controller(
    make_server: MakeServer, make_table: MakeTable
) -> None:
    """Grbl answers no ``?`` during its homing cycle (one report when it ends); the driver
    had taken 2 s of silence for a dead controller, so every homing of a real table longer
    than that failed (found against grbl-sim). A cycle of about 3 s, in real time."""
    settings = {**QUICK_TABLE, 22: 1.0, 25: 300.0}  # homing enabled, seeking at 5 deg/s
    server = make_server(GrblSimulator(settings=settings), time_scale=1.0)
    server.simulator.motion.position_deg = 15.0  # the switch 15 degrees away
    table = make_table(server, BUDGET)
    assert table.status().state == "Alarm"
    before = table.statuses_received
    assert table.home() == pytest.approx(0.0)
    assert table.statuses_received - before <= 2  # the coalesced report, then home()'s own
    assert table.position_known


class _GonePort:
    """A serial port that was unplugged: reads wait until released, then fail; writes fail."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.in_waiting = 0

    def read(self, size: int = 1) -> bytes:
        self.release.wait(10.0)
        raise OSError("device reports readiness to read but returned no data")

    def write(self, data: bytes, /) -> int | None:
        raise OSError("[Errno 5] Input/output error")

    def close(self) -> None:
        self.release.set()


def test_a_write_that_finds_the_port_gone_raises_only_after_the_listeners_were_told() -> None:
    """The reader and a write both find the port gone; whichever is second waits for the
    first to have told the listeners (grbl-sim unplugged mid-move: the move raised
    TableDisconnected before the ``disconnected`` signal fired, 1 run in 28)."""
    events: list[str] = []
    telling, told = threading.Event(), threading.Event()

    def on_disconnect(reason: str) -> None:
        events.append("told")
        telling.set()
        told.wait(10.0)  # a listener that takes its time (the GUI's signal, a log handler)

    port = _GonePort()
    link = GrblLink(port, lambda reply: None, on_disconnect)
    link.start()
    port.release.set()  # the reader finds the port gone first
    assert telling.wait(10.0)
    outcome: list[BaseException] = []

    def write() -> None:
        try:
            with link.cond:  # as a move's status poll writes, under the link's lock
                link.write(b"?")
        except TableDisconnected as error:
            events.append("raised")
            outcome.append(error)

    writer = threading.Thread(target=write)
    writer.start()
    writer.join(0.3)
    assert events == ["told"]  # not raised while the listeners are still being told
    told.set()
    writer.join(10.0)
    assert events == ["told", "raised"] and outcome
    assert link.state.disconnected is not None and link.state.position_lost  # all told
    link.close()


# --- issue 23, finding 6: failures under line noise within the budget; unknown position ----

BUDGET = TableTimeouts()
"""The shipped bounds: any failure reported within ``failure_s`` (2 s)."""


def test_a_lost_answer_to_the_move_line_is_reported_at_reply_s(
    server: PtyGrblServer, make_table: MakeTable
) -> None:
    clock = FakeClock()
    table = make_table(server, BUDGET, clock)
    lines = len(server.simulator.executed_lines)
    server.simulator.garble(count=1, skip=1)  # status, then the ok of G0 is lost
    mover, outcome = goto_in_background(table, 15.0)
    assert wait_real(lambda: len(server.simulator.executed_lines) > lines)  # G0 ran
    clock.advance(BUDGET.reply_s - 0.01)
    time.sleep(0.2)
    assert mover.is_alive()
    clock.advance(0.02)
    mover.join(timeout=20.0)
    assert isinstance(outcome[0], TableTimeout)
    assert BUDGET.reply_s <= BUDGET.failure_s
    assert table.goto_deg(20.0) == pytest.approx(20.0)  # back in step, no wrong angle


def test_a_lost_answer_to_the_barrier_is_reported_within_the_budget(
    server: PtyGrblServer, make_table: MakeTable
) -> None:
    clock = FakeClock()
    table = make_table(server, BUDGET, clock)
    server.simulator.garble(count=1, skip=2)  # status, ok of G0, then the ok of G4 P0 is lost
    mover, outcome = goto_in_background(table, 15.0)  # its move bound: over 5 s
    barrier = BARRIER_LINE.replace(" ", "")
    assert wait_real(lambda: barrier in server.simulator.executed_lines)
    took_s = advance_while_polling(table, clock, mover, BUDGET.poll_s, 20.0)
    assert isinstance(outcome[0], TableTimeout)
    assert "lost" in str(outcome[0])
    assert took_s <= BUDGET.failure_s  # idle without an answer, not the move bound
    assert server.simulator.angle_deg == pytest.approx(15.0)
    assert table.goto_deg(25.0) == pytest.approx(25.0)


def test_moves_are_refused_while_the_position_is_unknown(
    server: PtyGrblServer, table: GrblTable
) -> None:
    assert table.reset().state == "Idle"  # Ctrl-X at rest: no alarm, but the angle is unknown
    sent = len(server.simulator.executed_lines)
    with pytest.raises(TablePositionUnknown):
        table.goto_deg(30.0)
    assert len(server.simulator.executed_lines) == sent
    assert server.simulator.angle_deg == 0.0
    table.confirm_position_known()
    assert table.goto_deg(30.0) == pytest.approx(30.0)


def test_a_resync_whose_own_answer_was_lost_does_not_leave_the_link_out_of_step(
    server: PtyGrblServer, table: GrblTable
) -> None:
    server.simulator.garble(count=1, skip=1)  # status, then the ok of G0 is lost
    with pytest.raises(TableTimeout):
        table.goto_deg(10.0)
    server.simulator.garble(count=1, skip=1)  # status, then the resync's [GC:...] is lost
    with pytest.raises(TableTimeout, match=r"\$G"):
        table.goto_deg(20.0)
    for target_deg in (30.0, 40.0):  # the next resync flushes both; back in step for good
        assert table.goto_deg(target_deg) == pytest.approx(target_deg)


# --- what the real firmware does that a simulator might not (gnea/grbl 1.1h's sources) ------


def test_a_critical_alarm_is_reported_without_asking_the_silent_controller(
    server: PtyGrblServer, make_table: MakeTable
) -> None:
    """After a hard or soft limit Grbl 1.1h answers nothing, not even ``?``, until Ctrl-X
    (protocol.c): the alarm is reported at once (the clock never moves here, so a query would
    wait for ever), and an unlock or a homing is refused as the alarm, not timed out."""
    clock = FakeClock()
    table = make_table(server, clock=clock)
    said: list[str] = []
    table.message_received.connect(said.append)
    server.simulator.inject_alarm(1)
    assert wait_real(lambda: "Reset to continue" in said)  # after the ALARM:1 line
    outcome_status: list[TableStatus] = []
    asked, outcome = _in_background(lambda: outcome_status.append(table.status()))
    asked.join(timeout=20.0)
    assert outcome == [] and len(outcome_status) == 1
    status = outcome_status[0]
    assert (status.state, status.alarm_code, status.position_known) == ("Alarm", 1, False)
    for operator_action in (table.unlock, table.home):
        with pytest.raises(TableAlarm, match="reset it"):
            operator_action()
    assert not any(line in ("$X", "$H") for line in server.simulator.executed_lines)


def test_unlock_and_home_are_refused_while_a_hold_suspends_the_controller(
    server: PtyGrblServer, make_table: MakeTable
) -> None:
    """Grbl runs no line while held: a ``$H`` sent then would wait in its buffer and home the
    table later, after a resume."""
    table = make_table(server)
    assert table.hold().state == "Hold"
    for operator_action in (table.unlock, table.home):
        with pytest.raises(TableHeld, match="resume"):
            operator_action()
    assert not any(line in ("$X", "$H") for line in server.simulator.executed_lines)


def test_a_controller_reporting_in_inches_is_refused_at_connect(
    make_server: Callable[..., PtyGrblServer],
) -> None:
    server = make_server(GrblSimulator(settings={13: 1}))
    with pytest.raises(TableMisconfigured, match=r"\$13=0"):
        open_table(server.device_path, timeouts=FAST)
