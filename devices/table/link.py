"""The serial link to a Grbl controller: one reader thread, strict ok/error accounting.

Grbl answers every line with exactly one ``ok`` or ``error:N``, in order. The link keeps a
FIFO of lines waiting for their answer; a line whose wait was given up (timeout, alarm, hold)
stays in the FIFO as *stale*, so its late answer is still matched to it. Before the next line
is sent, stale lines are flushed by a resync: ``$G`` is sent and its ``[GC:...]`` line marks
the point after which nothing older can be answered (an answer lost to noise is dropped there).
Asynchronous lines (status, ``ALARM:N``, ``[MSG:...]``, the banner) are handled whenever they
arrive. Between a Ctrl-X and the banner that follows, ``ok``/``error`` are ignored.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from devices.table import protocol as p
from devices.table.codes import POSITION_LOST_ALARMS
from devices.table.errors import (
    TableDisconnected,
    TableException,
    TableHeld,
    TableReset,
    TableTimeout,
)

log = logging.getLogger(__name__)

READ_POLL_S = 0.05
MAX_STALE_LINES = 3
TELL_DISCONNECT_S = 5.0
"""How long a second thread that finds the port gone waits for the first to have told the
listeners, before it raises anyway (a listener that hangs does not hang the driver)."""


class SerialPort(Protocol):
    """What the link needs of a pyserial ``Serial`` (or anything that behaves like one)."""

    @property
    def in_waiting(self) -> int: ...

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes, /) -> int | None: ...

    def close(self) -> None: ...


@dataclass
class _Slot:
    line: str
    reply: p.Reply | None = None
    error: TableException | None = None
    stale: bool = False
    sync: bool = False
    deadline_s: float = 0.0

    @property
    def done(self) -> bool:
        return self.reply is not None or self.error is not None


@dataclass
class ControllerState:
    """What the reader has learnt; read under :attr:`GrblLink.cond`."""

    alarm_code: int | None = None
    in_alarm: bool = False
    critical: bool = False
    position_lost: bool = False
    status: p.StatusReport | None = None
    wco_x_deg: float = 0.0
    settings: dict[int, float] = field(default_factory=dict)
    banners: int = 0
    alarms: int = 0
    statuses: int = 0
    last_status_s: float = 0.0
    garbled_lines: int = 0
    disconnected: str | None = None


class GrblLink:
    """Owns the port once started. ``on_line`` sees every parsed line (before the link
    accounts for it) and ``on_disconnect`` the loss of the port, both on the reader thread:
    they must not block. Every deadline is on ``clock`` (tests advance a fake one); waits
    wake at least every ``READ_POLL_S`` of real time to look at it."""

    def __init__(
        self,
        port: SerialPort,
        on_line: Callable[[p.Reply], None],
        on_disconnect: Callable[[str], None],
        clock: Callable[[], float] = time.monotonic,
        failure_s: float = 2.0,
    ) -> None:
        self._port = port
        self.clock = clock
        self.failure_s = failure_s
        """Every failure (silence, a lost answer) is reported within this many seconds."""
        self._on_line = on_line
        self._on_disconnect = on_disconnect
        self.cond = threading.Condition()
        self.state = ControllerState()
        self._pending: deque[_Slot] = deque()
        self._resetting = False
        self._splitter = p.LineSplitter()
        self._send_lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._closing = threading.Event()
        self._disconnect_seen = False
        self._telling: threading.Thread | None = None
        self._thread = threading.Thread(target=self._read_loop, name="grbl-reader", daemon=True)

    def start(self) -> None:
        if not self._thread.is_alive():
            self._thread.start()

    def close(self) -> None:
        self._closing.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        try:
            self._port.close()
        except Exception as error:  # closing a port that is already gone
            log.debug("closing the port: %s", error)

    # --- writing --------------------------------------------------------------------------

    def write(self, data: bytes) -> None:
        with self.cond:
            self._raise_if_disconnected()
        try:
            with self._write_lock:
                self._port.write(data)
        except Exception as error:
            self._disconnect(f"write failed: {error}")
            raise TableDisconnected(f"table disconnected: {error}") from error

    def send_reset(self) -> None:
        """Ctrl-X: every waiting line fails with TableReset; answers until the banner are void."""
        with self.cond:
            self._resetting = True
            self._fail_pending(TableReset("controller reset while the line was running"))
        self.write(p.SOFT_RESET)

    def send_line(
        self,
        line: str,
        timeout_s: float,
        interrupted: Callable[[], TableException | None],
        poll_s: float | None = None,
    ) -> p.Reply:
        """Send one line and wait for its ``ok`` (returned) or ``error:N`` (returned too).

        ``interrupted`` is checked while waiting: an exception it returns is raised and the
        line is left stale. A resync before the line shares its deadline (no stacked timeouts).
        With ``poll_s`` (a line that waits for motion), a ``?`` is sent that often while
        waiting, so an Alarm is seen even if its ``ALARM:N`` line was lost, and the wait fails
        as soon as the controller stops answering for ``failure_s`` or reports Idle for
        ``failure_s / 2`` without the answer (lost to noise), whatever ``timeout_s`` is left.
        Raises TableTimeout, TableDisconnected or TableReset.
        """
        data = p.encode_line(line)
        with self._send_lock:
            started_s = self.clock()
            waited_for_a_move = self._resync(
                started_s + (self.failure_s if poll_s is not None else timeout_s)
            )
            slot = _Slot(line)
            with self.cond:
                self._pending.append(slot)
            self.write(data)
            base_s = self.clock() if poll_s is not None or waited_for_a_move else started_s
            return self._wait_slot(slot, base_s + timeout_s, timeout_s, interrupted, poll_s)

    def _wait_slot(
        self,
        slot: _Slot,
        deadline_s: float,
        timeout_s: float,
        interrupted: Callable[[], TableException | None],
        poll_s: float | None = None,
    ) -> p.Reply:
        slot.deadline_s = deadline_s
        watch = _Liveness(self, poll_s) if poll_s is not None else None
        with self.cond:
            while not slot.done:
                self._raise_if_disconnected()
                stop = interrupted() or (watch.check(slot.line) if watch else None)
                left_s = deadline_s - self.clock()
                if stop is None and left_s <= 0.0:
                    stop = TableTimeout(f"no answer to {slot.line!r} within {timeout_s:.1f} s")
                if stop is not None:
                    slot.stale = True
                    if not isinstance(stop, TableHeld):  # only a held move may still run
                        slot.deadline_s = self.clock()
                    raise stop
                self.cond.wait(min(left_s, READ_POLL_S))
            if slot.reply is not None:
                return slot.reply
            raise slot.error or TableException(f"no answer to {slot.line!r}")

    def _resync(self, deadline_s: float) -> bool:
        """Flush stale lines by ``deadline_s`` (later if a stale move may still be running:
        then True)."""
        with self.cond:
            stale = sum(1 for s in self._pending if s.stale)
            last_deadline_s = max((s.deadline_s for s in self._pending), default=0.0)
        if stale == 0:
            return False
        if stale > MAX_STALE_LINES:
            raise TableTimeout(
                f"controller out of step ({stale} lines unanswered); reset the table"
            )
        # a stale line may still be running (a held move that was resumed): it keeps its bound
        extended = last_deadline_s > deadline_s
        deadline_s = max(deadline_s, last_deadline_s)
        log.info("resynchronising with the controller (%d stale lines)", stale)
        slot = _Slot(p.PARSER_STATE_LINE, sync=True)
        with self.cond:
            self._pending.append(slot)
        self.write(p.encode_line(p.PARSER_STATE_LINE))
        self._wait_slot(slot, deadline_s, deadline_s - self.clock(), lambda: None)
        return extended

    # --- waiting for asynchronous lines -----------------------------------------------------

    def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Wait (under :attr:`cond`) until ``predicate()``; False on timeout."""
        return self._wait_until_deadline(predicate, self.clock() + timeout_s)

    def _wait_until_deadline(self, predicate: Callable[[], bool], deadline_s: float) -> bool:
        with self.cond:
            while not predicate():
                self._raise_if_disconnected()
                left_s = deadline_s - self.clock()
                if left_s <= 0.0:
                    return False
                self.cond.wait(min(left_s, READ_POLL_S))
            return True

    def query_status(self, timeout_s: float, attempts: int = 3) -> p.StatusReport:
        """Send ``?`` and return the first status report received after it, asking again
        every ``timeout_s``; the attempts share one deadline of at most ``failure_s`` from
        the first (no stacked timeouts)."""
        started_s = self.clock()
        budget_s = min(attempts * timeout_s, self.failure_s)
        for attempt in range(1, attempts + 1):
            with self.cond:
                seen = self.state.statuses
            self.write(p.STATUS_QUERY)
            deadline_s = started_s + min(attempt * timeout_s, budget_s)
            if self._wait_until_deadline(self._newer_status_than(seen), deadline_s):
                with self.cond:
                    status = self.state.status
                if status is not None:
                    return status
        raise TableTimeout(f"no status report within {budget_s:.1f} s ({attempts} queries)")

    def _newer_status_than(self, seen: int) -> Callable[[], bool]:
        return lambda: self.state.statuses > seen

    # --- reading ----------------------------------------------------------------------------

    def _read_loop(self) -> None:
        while not self._closing.is_set():
            try:
                data = self._port.read(1)
                if data:
                    data += self._port.read(self._port.in_waiting)
            except Exception as error:
                if not self._closing.is_set():
                    self._disconnect(f"read failed: {error}")
                return
            for raw in self._splitter.feed(data):
                self._handle(p.parse_line(raw))

    def _handle(self, reply: p.Reply) -> None:
        try:  # first the listeners, so the operator is told before a waiting move raises
            self._on_line(reply)
        except Exception:
            log.exception("handler of %r failed", reply)
        with self.cond:
            self._account(reply)
            self.cond.notify_all()

    def _account(self, reply: p.Reply) -> None:
        state = self.state
        if isinstance(reply, p.Ok | p.ErrorReply):
            self._answer(reply)
        elif isinstance(reply, p.StatusReport):
            state.status, state.statuses = reply, state.statuses + 1
            state.last_status_s = self.clock()
            state.wco_x_deg = reply.wco[0] if reply.wco else state.wco_x_deg
            state.in_alarm = reply.state == "Alarm"
            if not state.in_alarm:
                state.alarm_code, state.critical = None, False
        elif isinstance(reply, p.AlarmReply):
            state.alarm_code, state.in_alarm, state.alarms = reply.code, True, state.alarms + 1
            state.position_lost |= reply.code in POSITION_LOST_ALARMS
        elif isinstance(reply, p.Message):
            self._account_message(reply.text)
        elif isinstance(reply, p.Banner):
            self._account_banner()
        elif isinstance(reply, p.Feedback) and reply.tag == "GC":
            self._drop_before_sync()
        elif isinstance(reply, p.SettingLine):
            state.settings[reply.number] = reply.value
        elif isinstance(reply, p.Garbled):
            state.garbled_lines += 1
            log.warning("garbled line from the controller: %r", reply.raw)

    def _answer(self, reply: p.Ok | p.ErrorReply) -> None:
        if self._resetting:
            log.debug("ignoring %r answered during a reset", reply)
        elif not self._pending:
            log.warning("unexpected %r: no line is waiting for an answer", reply)
        else:
            self._pending.popleft().reply = reply

    def _account_message(self, text: str) -> None:
        if text == "Reset to continue":
            self.state.critical = self.state.in_alarm = True
        elif text == "'$H'|'$X' to unlock":
            self.state.in_alarm = True
        elif text == "Caution: Unlocked":
            self.state.in_alarm, self.state.alarm_code = False, None

    def _account_banner(self) -> None:
        if not self._resetting and self.state.banners > 0:
            log.warning("the controller reset itself; the table position is unknown")
            self.state.position_lost = True
        self._resetting = False
        self._fail_pending(TableReset("controller reset while the line was running"))
        self.state.critical = False
        self.state.banners += 1

    def _drop_before_sync(self) -> None:
        """A ``[GC:...]`` line: everything before the waiting resync was lost, including an
        earlier resync given up on (its own ``[GC:...]`` garbled), which would otherwise
        take this resync's answer and leave the link out of step for good."""
        while self._pending and not (self._pending[0].sync and not self._pending[0].stale):
            lost = self._pending.popleft()
            lost.error = TableTimeout(f"the answer to {lost.line!r} was lost")
            log.warning("answer to %r lost (noise on the line?)", lost.line)

    def _fail_pending(self, error: TableException) -> None:
        while self._pending:
            self._pending.popleft().error = error

    def _disconnect(self, reason: str) -> None:
        """Tell the listeners, then fail every waiting line. Called by whichever thread finds
        the port gone first (the reader, a write); a second one waits until the listeners
        were told, so no TableDisconnected is raised before they hear of it."""
        with self.cond:
            first = not self._disconnect_seen
            if first:
                self._disconnect_seen = True
                self._telling = threading.current_thread()
        if not first:
            if self._telling is not threading.current_thread():  # not a listener's own write
                with self.cond:  # waiting releases the lock, even one this thread held already
                    self.cond.wait_for(
                        lambda: self.state.disconnected is not None, TELL_DISCONNECT_S
                    )
            return
        log.error("table disconnected: %s", reason)
        try:  # first the listeners, so the operator is told before a waiting move raises
            self._on_disconnect(reason)
        except Exception:
            log.exception("disconnect handler failed")
        with self.cond:
            self.state.disconnected = reason
            self.state.position_lost = True
            self._fail_pending(TableDisconnected(f"table disconnected: {reason}"))
            self.cond.notify_all()

    def _raise_if_disconnected(self) -> None:
        if self.state.disconnected is not None:
            raise TableDisconnected(f"table disconnected: {self.state.disconnected}")


class _Liveness:
    """While a line waits for motion: polls ``?`` every ``poll_s`` and tells when the
    controller went silent, or sits Idle without answering the line (its answer was lost)."""

    def __init__(self, link: GrblLink, poll_s: float) -> None:
        self._link, self._poll_s = link, poll_s
        now_s = link.clock()
        self._next_poll_s = now_s + poll_s
        self._heard_s = now_s
        self._statuses = link.state.statuses
        self._idle_since_s: float | None = None

    def check(self, line: str) -> TableException | None:
        """Called under the link's lock at every wake-up of the wait."""
        link, state, now_s = self._link, self._link.state, self._link.clock()
        if now_s >= self._next_poll_s:
            self._next_poll_s = now_s + self._poll_s
            link.write(p.STATUS_QUERY)
        if state.statuses > self._statuses:
            self._statuses, self._heard_s = state.statuses, state.last_status_s
            idle = state.status is not None and state.status.state == "Idle"
            if not idle:
                self._idle_since_s = None
            elif self._idle_since_s is None:
                self._idle_since_s = now_s
        if now_s - self._heard_s > link.failure_s:
            return TableTimeout(
                f"controller silent for {link.failure_s:.1f} s while waiting for {line!r}"
            )
        if self._idle_since_s is not None and now_s - self._idle_since_s > link.failure_s / 2:
            return TableTimeout(f"controller idle but the answer to {line!r} was lost")
        return None
