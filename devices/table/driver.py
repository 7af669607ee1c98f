"""The rotary table driver: Grbl 1.1 over a serial port (``spec/turntable-grbl.md``).

The driver is handed an open pyserial-like port and never opens one itself; :func:`open_table`
is the small factory that opens a device path or pyserial URL. A move is ``G21 G90 G0 X<deg>``
(``ok`` = queued), then ``G4 P0`` (``ok`` = motion buffer empty), then ``?`` and the read-back
position must be within ``tolerance_deg`` of the target. In Alarm the driver refuses to move;
it never sends ``$X`` or ``$H`` unless the operator calls :meth:`GrblTable.unlock` or
:meth:`GrblTable.home`. Signals are emitted on the reader thread.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from psygnal import Signal

from devices.table import protocol as p
from devices.table.codes import POSITION_LOST_ALARMS, alarm_meaning
from devices.table.errors import (
    TableAlarm,
    TableDisconnected,
    TableError,
    TableException,
    TableHeld,
    TableMisconfigured,
    TableMissedTarget,
    TablePositionUnknown,
    TableReset,
    TableTimeout,
)
from devices.table.link import READ_POLL_S, GrblLink, SerialPort
from devices.table.park import ParkFile, ParkState

log = logging.getLogger(__name__)

BAUD_RATE = 115200
SUSPENDED_STATES = ("Hold", "Door", "Sleep")
"""States in which Grbl runs no line until a resume (``~``) or a reset."""
REPORT_INCHES_SETTING = 13
"""``$13=1``: Grbl reports positions in inches (the table's degrees divided by 25.4)."""
TOLERANCE_DEG = 0.2


@dataclass(frozen=True)
class TableTimeouts:
    """Bounds on every wait, seconds. A move waits its estimated travel time x 1.5 plus
    ``move_margin_s`` when the controller's ``$110``/``$120`` are known, else ``move_max_s``;
    but any failure is reported within ``failure_s``: the status queries' retries share it, a
    resync shares its line's ``reply_s``, and a move fails once the controller stops answering
    its polls for ``failure_s`` or reports Idle for half of it without answering the barrier."""

    banner_s: float = 2.0
    reply_s: float = 1.0
    status_s: float = 0.5
    move_margin_s: float = 5.0
    move_max_s: float = 120.0
    hold_s: float = 10.0
    poll_s: float = 0.25
    failure_s: float = 2.0


@dataclass(frozen=True)
class TableStatus:
    """One status report, with the driver's knowledge of the position and alarm."""

    state: str
    substate: int | None
    position_deg: float
    position_known: bool
    alarm_code: int | None

    def __str__(self) -> str:
        state = self.state if self.substate is None else f"{self.state}:{self.substate}"
        if self.alarm_code:
            state += f" (ALARM:{self.alarm_code}: {alarm_meaning(self.alarm_code)})"
        known = "" if self.position_known else ", position unknown: home before capturing"
        return f"{state} at {self.position_deg:.3f} deg{known}"


class GrblTable:
    """A rotary table behind a Grbl 1.1 controller. Thread-safe; one move at a time."""

    alarm_raised = Signal(int, str)
    message_received = Signal(str)
    position_deg_changed = Signal(float)
    position_unknown = Signal(str)
    disconnected = Signal(str)

    def __init__(
        self,
        port: SerialPort,
        *,
        timeouts: TableTimeouts | None = None,
        tolerance_deg: float = TOLERANCE_DEG,
        clock: Callable[[], float] = time.monotonic,
        park_file: ParkFile | None = None,
        port_name: str = "",
    ) -> None:
        """``clock`` times every bound in :class:`TableTimeouts` (a fake one in tests).
        ``park_file``: where this port's table was left (:mod:`devices.table.park`), under
        ``port_name``; without one a power-up is trusted, as before."""
        self.timeouts = timeouts or TableTimeouts()
        self.tolerance_deg = tolerance_deg
        self._clock = clock
        self._link = GrblLink(
            port, self._on_line, self.disconnected.emit, clock, self.timeouts.failure_s
        )
        self._holds = 0
        self._position_known = False
        self._last_position_deg = 0.0
        self._park_file = park_file
        self._port_name = port_name
        self._left: ParkState | None = None
        """What this driver last wrote to ``park_file`` (a move does no file I/O to repeat it)."""
        self.restarted_on_open = False
        """True when the controller announced itself as the port opened, before any Ctrl-X
        of the driver's: a power-up (DTR), machine position 0 where the table stands."""

    # --- connection -----------------------------------------------------------------------

    def connect(self) -> TableStatus:
        """Wait for the banner (Ctrl-X if none comes), read status and settings."""
        self._link.start()
        state = self._link.state
        self.restarted_on_open = self._link.wait_until(
            lambda: state.banners > 0, self.timeouts.banner_s
        )
        if not self.restarted_on_open:
            log.info("no Grbl banner within %.1f s: sending Ctrl-X", self.timeouts.banner_s)
            self._link.send_reset()
            if not self._link.wait_until(lambda: state.banners > 0, self.timeouts.banner_s):
                raise TableTimeout(
                    f"no Grbl banner within {self.timeouts.banner_s:.1f} s, nor after a reset "
                    "(Ctrl-X): is a Grbl 1.1 controller on this port at 115200 baud?"
                )
        status = self.status()
        with self._link.cond:
            self._position_known = status.state != "Alarm" and not state.position_lost
        self._read_settings()
        if self.restarted_on_open and self._last_left() == "moved":
            self._forget_position(
                "the controller restarted as its port opened (DTR) and counts angles from "
                "where the table stands, which was not its zero when the port last closed: "
                "turn the table to its zero mark and confirm it, or home it"
            )
        return self.status()

    def close(self) -> None:
        """Stop the reader and close the port."""
        self._link.close()

    @property
    def position_known(self) -> bool:
        with self._link.cond:
            return self._position_known and not self._link.state.position_lost

    @property
    def statuses_received(self) -> int:
        """How many status reports the controller has sent (monitoring and tests)."""
        with self._link.cond:
            return self._link.state.statuses

    @property
    def settings(self) -> dict[int, float]:
        """The controller's ``$$`` settings as read at connect (``$110`` deg/min etc.)."""
        with self._link.cond:
            return dict(self._link.state.settings)

    # --- queries --------------------------------------------------------------------------

    def status(self) -> TableStatus:
        """The controller's state and the table angle. After a hard or soft limit (a critical
        alarm) Grbl 1.1 answers nothing, not even ``?``, until a reset: the alarm is reported
        at the last angle the controller sent, without asking (grblHAL would answer)."""
        with self._link.cond:
            if self._link.state.critical:  # the condition's lock is re-entrant
                code, known = self._link.state.alarm_code, self.position_known
                return TableStatus("Alarm", None, self._last_position_deg, known, code)
        report = self._link.query_status(self.timeouts.status_s)
        with self._link.cond:
            position_deg = report.machine_x_deg(self._link.state.wco_x_deg)
            position_deg -= self._link.state.wco_x_deg
            alarm_code = self._link.state.alarm_code if report.state == "Alarm" else None
        return TableStatus(
            report.state, report.substate, position_deg, self.position_known, alarm_code
        )

    def position_deg(self) -> float:
        """The table angle the controller reports now (work X = MPos - WCO), degrees."""
        return self.status().position_deg

    # --- motion -------------------------------------------------------------------------

    def goto_deg(self, target_deg: float) -> float:
        """Turn to ``target_deg`` and return the angle reached (checked within tolerance).

        Refused (:class:`TablePositionUnknown`, no line sent) while the position is unknown."""
        move_line = p.goto_line(target_deg)
        start = self.status()
        self._refuse_if_not_ready(start)
        if not self.position_known:
            raise TablePositionUnknown(
                "table position unknown (after a reset, a lost-steps alarm or an unplug): "
                "operator: home the table or confirm its angle; moves refused until then"
            )
        interrupted = self._interruption_since()
        timeout_s = self._move_timeout_s(abs(target_deg - start.position_deg))
        self._leave("moved")
        self._run(move_line, self.timeouts.reply_s, interrupted)
        self._run(p.BARRIER_LINE, timeout_s, interrupted, poll=True)
        stop = interrupted()
        if stop is not None:
            raise stop
        end = self.status()
        self._refuse_if_not_ready(end)
        if end.state != "Idle":
            raise TableException(f"controller reports {end.state} after the move barrier")
        if abs(end.position_deg - target_deg) > self.tolerance_deg:
            raise TableMissedTarget(target_deg, end.position_deg, self.tolerance_deg)
        log.info("table at %.3f deg (target %.3f deg)", end.position_deg, target_deg)
        return end.position_deg

    def park(self) -> float:
        """Turn to machine zero (MPos 0: the work angle minus the work offset) and return the
        work angle reached. Opening the port resets most boards through DTR, and Grbl starts
        a power-up with its machine position at 0 where the table stands (a Ctrl-X keeps it):
        a table parked there keeps its angles across closing and opening the port."""
        with self._link.cond:
            wco_x_deg = self._link.state.wco_x_deg
        reached_deg = self.goto_deg(0.0 - wco_x_deg)  # 0.0, not -0.0, with no offset
        self._leave("parked")
        return reached_deg

    def hold(self) -> TableStatus:
        """Feed hold (``!``): controlled stop; returns once stopped (``Hold:0``)."""
        with self._link.cond:
            self._holds += 1
            self._link.cond.notify_all()
        self._link.write(p.FEED_HOLD)
        deadline_s = self._clock() + self.timeouts.hold_s
        while self._clock() < deadline_s:
            status = self.status()
            if status.state in ("Idle", "Alarm") or (status.state, status.substate) == (
                "Hold",
                0,
            ):
                return status
            time.sleep(READ_POLL_S)
        raise TableTimeout(f"table not stopped within {self.timeouts.hold_s:.1f} s of a hold")

    def resume(self) -> None:
        """Cycle start (``~``): a held move carries on to its target."""
        self._link.write(p.CYCLE_START)

    def reset(self) -> TableStatus:
        """Ctrl-X: immediate stop and controller reset. The position is unknown afterwards."""
        with self._link.cond:
            self._position_known = False
            banners = self._link.state.banners
        self._link.send_reset()
        if not self._link.wait_until(
            lambda: self._link.state.banners > banners, self.timeouts.banner_s
        ):
            raise TableTimeout(f"no banner within {self.timeouts.banner_s:.1f} s of a reset")
        self.position_unknown.emit("controller reset: home the table before the next capture")
        return self.status()

    def home(self) -> float:
        """Operator-requested homing cycle (``$H``); the position is known afterwards."""
        with self._link.cond:
            critical = self._link.state.critical
        if critical:  # Grbl ignores every line until a reset
            raise self._alarm_error()
        self._refuse_while_suspended("home ($H)")
        with self._link.cond:
            alarms = self._link.state.alarms

        def new_alarm() -> TableException | None:
            return self._alarm_error() if self._link.state.alarms > alarms else None

        # no polls: Grbl answers no ``?`` during its homing cycle (one report when it ends), so
        # silence there is no dead controller; an ALARM line (a switch not found) still ends it
        self._run(p.HOME_LINE, self._homing_timeout_s(), new_alarm)
        with self._link.cond:
            self._position_known = True
            self._link.state.position_lost = False
        return self.position_deg()

    def unlock(self) -> TableStatus:
        """Operator-requested alarm unlock (``$X``). The position stays unknown if it was."""
        with self._link.cond:
            critical = self._link.state.critical
        if critical:
            raise self._alarm_error()
        self._refuse_while_suspended("unlock ($X)")
        self._run(p.UNLOCK_LINE, self.timeouts.reply_s, lambda: None)
        return self.status()

    def confirm_position_known(self) -> None:
        """The operator confirms the reported angle is right (e.g. checked the zero mark)."""
        with self._link.cond:
            self._position_known = True
            self._link.state.position_lost = False
            machine_deg = self._last_position_deg + self._link.state.wco_x_deg
        if abs(machine_deg) <= self.tolerance_deg:
            self._leave("parked")  # at machine zero: a power-up there keeps the angles

    def _last_left(self) -> str | None:
        return None if self._park_file is None else self._park_file.state(self._port_name)

    def _leave(self, state: ParkState) -> None:
        if self._park_file is not None and state != self._left:
            self._park_file.record(self._port_name, state)
            self._left = state

    def _forget_position(self, reason: str) -> None:
        log.warning("table position unknown: %s", reason)
        with self._link.cond:
            self._position_known = False
        self.position_unknown.emit(reason)

    # --- helpers --------------------------------------------------------------------------

    def _run(
        self,
        line: str,
        timeout_s: float,
        interrupted: Callable[[], TableException | None],
        *,
        poll: bool = False,
    ) -> None:
        poll_s = self.timeouts.poll_s if poll else None
        reply = self._link.send_line(line, timeout_s, interrupted, poll_s=poll_s)
        if isinstance(reply, p.ErrorReply):
            raise TableError(reply.code, reply.meaning, line)

    def _refuse_while_suspended(self, what: str) -> None:
        """Grbl runs no line while a feed hold, an open door or sleep suspends it: the line
        would wait in its buffer (a timeout here) and run later, after a resume."""
        status = self.status()
        if status.state in SUSPENDED_STATES:
            raise TableHeld(
                f"table is in {status.state}: resume (~) or reset it before asking to {what}"
            )

    def _refuse_if_not_ready(self, status: TableStatus) -> None:
        if status.state == "Alarm":
            raise self._alarm_error()
        if status.state in ("Hold", "Door"):
            raise TableHeld(f"table is in {status.state}: resume (~) or reset it before moving")

    def _interruption_since(self) -> Callable[[], TableException | None]:
        with self._link.cond:
            alarms, holds = self._link.state.alarms, self._holds

        def interrupted() -> TableException | None:
            state = self._link.state
            if state.alarms > alarms or state.in_alarm:
                return self._alarm_error()
            if self._holds > holds:
                return TableHeld("move interrupted by a feed hold; resume (~) to finish it")
            return None

        return interrupted

    def _alarm_error(self) -> TableAlarm:
        with self._link.cond:
            code, critical = self._link.state.alarm_code, self._link.state.critical
        meaning = alarm_meaning(code) if code else "controller locked in Alarm"
        advice = "operator: check the table, then unlock ($X) or home ($H)"
        if critical:
            advice = "operator: check the table, reset it (Ctrl-X), then unlock or home"
        return TableAlarm(code or None, meaning, advice + "; moves refused until then")

    def _homing_timeout_s(self) -> float:
        """Grbl's homing at most: each axis's search over 1.5 x its max travel (``$130``-``$132``:
        the firmware's default cycles home Z, then X and Y, whatever the table uses) at ``$25``
        (seek rate), then the locating approach and pull-off over up to 5 x ``$27`` each at
        ``$24`` (feed rate); x 1.5 plus ``move_margin_s``. ``move_max_s`` when those settings
        are not known."""
        settings = self.settings
        seek_deg_s, feed_deg_s = settings.get(25, 0.0) / 60.0, settings.get(24, 0.0) / 60.0
        travels = [settings.get(number, 0.0) for number in (130, 131, 132)]
        if seek_deg_s <= 0.0 or feed_deg_s <= 0.0 or travels[0] <= 0.0:
            return self.timeouts.move_max_s
        locate_s = 3 * 5.0 * settings.get(27, 0.0) / feed_deg_s
        cycle_s = sum(1.5 * travel / seek_deg_s + locate_s for travel in travels if travel > 0.0)
        return 1.5 * cycle_s + self.timeouts.move_margin_s

    def _move_timeout_s(self, distance_deg: float) -> float:
        settings = self.settings
        rate_deg_s = settings.get(110, 0.0) / 60.0
        accel_deg_s2 = settings.get(120, 0.0)
        if rate_deg_s <= 0.0 or accel_deg_s2 <= 0.0:
            return self.timeouts.move_max_s
        if distance_deg >= rate_deg_s**2 / accel_deg_s2:
            travel_s = distance_deg / rate_deg_s + rate_deg_s / accel_deg_s2
        else:
            travel_s = 2.0 * math.sqrt(distance_deg / accel_deg_s2)
        return 1.5 * travel_s + self.timeouts.move_margin_s

    def _read_settings(self) -> None:
        try:
            self._run(p.SETTINGS_LINE, self.timeouts.reply_s, lambda: None)
        except (TableError, TableTimeout, TableReset) as error:
            log.warning("could not read the controller settings ($$): %s", error)
            return
        if self.settings.get(REPORT_INCHES_SETTING):
            raise TableMisconfigured(
                f"the controller reports positions in inches (${REPORT_INCHES_SETTING}=1): the "
                f"table's angles would read 25.4 times too small; send "
                f"${REPORT_INCHES_SETTING}=0 (e.g. from a serial terminal) and connect again"
            )

    def _on_line(self, reply: p.Reply) -> None:
        if isinstance(reply, p.AlarmReply):
            log.error("ALARM:%d from the table: %s", reply.code, reply.meaning)
            self.alarm_raised.emit(reply.code, reply.meaning)
            if reply.code in POSITION_LOST_ALARMS:
                self.position_unknown.emit(f"ALARM:{reply.code}: {reply.meaning}")
        elif isinstance(reply, p.Message):
            log.info("table controller says: %s", reply.text)
            self.message_received.emit(reply.text)
        elif isinstance(reply, p.StatusReport):
            wco_x_deg = reply.wco[0] if reply.wco else self._link.state.wco_x_deg
            self._last_position_deg = reply.machine_x_deg(wco_x_deg) - wco_x_deg
            self.position_deg_changed.emit(self._last_position_deg)


def open_table(
    url_or_path: str,
    *,
    timeouts: TableTimeouts | None = None,
    connect: bool = True,
    park_file: ParkFile | None = None,
) -> GrblTable:
    """Open ``url_or_path`` (``/dev/ttyUSB0``, ``socket://host:port``...) at 115200 baud and
    return the driver, connected unless ``connect`` is False; ``park_file`` remembers where
    this port's table was left (:mod:`devices.table.park`)."""
    import serial

    try:
        port = serial.serial_for_url(url_or_path, baudrate=BAUD_RATE, timeout=READ_POLL_S)
    except (serial.SerialException, OSError, ValueError) as error:
        raise TableDisconnected(f"cannot open serial port {url_or_path!r}: {error}") from error
    table = GrblTable(port, timeouts=timeouts, park_file=park_file, port_name=url_or_path)
    if connect:
        try:
            table.connect()
        except TableException:
            table.close()
            raise
    return table
