"""A simulated Grbl 1.1 controller driving the rotary table, speaking the firmware's bytes.

The model is transport-free: :meth:`GrblSimulator.receive` takes the bytes the host sent,
:meth:`GrblSimulator.advance` moves model time, :meth:`GrblSimulator.take_output` returns the
bytes the controller sent. :mod:`devices.table.pty_server` serves it on a pseudo-terminal.

It follows the firmware where the driver can tell: the banner, the status line (with WCO and
Ov fields on Grbl's refresh counters), one ``ok``/``error:N`` per line in order, ``G4`` as a
barrier that answers only once the planner is empty, real-time ``?`` ``!`` ``~`` Ctrl-X acting
at once even mid-line, Alarm locking G-code (``error:9``) until ``$X`` or ``$H``, a hard limit
(ALARM:1) ignoring every line until a reset, a reset while moving raising ALARM:3, check mode
(``$C``: G-code parsed and answered, nothing moves; ``$C`` again resets) and sleep (``$SLP``:
lines ignored until a reset, which comes up in Alarm).
Injectable faults: stall (hard limit), any alarm, silence, garbled bytes; the pty server adds
unplugging. Thread-safe: every public method takes the model's lock.
"""

from __future__ import annotations

import logging
import math
import random
import threading
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from devices.table import protocol as p
from devices.table.codes import CRITICAL_ALARMS, alarm_meaning, error_meaning
from devices.table.sim_gcode import GBlock, clean_line, parse_block
from devices.table.sim_motion import MotionModel, MoveBlock
from devices.table.sim_settings import (
    INTEGER_SETTINGS,
    SettingsError,
    check_setting,
    merged_settings,
)

log = logging.getLogger(__name__)

VERSION = "1.1h"
HELP = "$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x"


@dataclass
class _Wait:
    """The line Grbl is still executing: its ``ok`` comes when the wait ends."""

    kind: str  # "planner" (buffer full), "barrier" (G4), "homing" ($H)
    block: MoveBlock | None = None
    dwell_s: float = 0.0


@dataclass
class _Modal:
    motion: int = 0
    absolute: bool = True
    inches: bool = False
    feed_per_min: float = 0.0


class GrblSimulator:
    """The controller plus the table. ``angle_deg`` is where the table is (== MPos X)."""

    def __init__(
        self,
        *,
        settings: Mapping[int, float] | None = None,
        off_target_deg: float = 0.0,
        seed: int = 0,
        on_angle: Callable[[float], None] | None = None,
        status_in_critical_alarm: bool = False,
    ) -> None:
        """``status_in_critical_alarm``: answer ``?`` after a hard or soft limit, as grblHAL
        does; Grbl 1.1h (protocol.c) answers nothing but Ctrl-X there, the default."""
        self._lock = threading.RLock()
        self.status_in_critical_alarm = status_in_critical_alarm
        self.settings = merged_settings(settings)
        self.on_angle = on_angle
        self._rng = random.Random(seed)
        self._off_target_deg = abs(off_target_deg)
        self.motion = MotionModel(self.settings[120], settle_offset_deg=self._settle_offset)
        self._rx = bytearray()
        self._out = bytearray()
        self._wait: _Wait | None = None
        self._modal = _Modal()
        self._planned_x_deg = 0.0
        self._alarm_code: int | None = None
        self._critical = False
        self._limit_pin = False
        self._silent = False
        self._report_after_homing = False
        self._check_mode = False
        self._asleep = False
        self._reset_after_answer = False
        self._garble_skip = 0
        self._garble_count = 0
        self._wco_counter = 0
        self._ovr_counter = 0
        self._last_angle_deg = 0.0
        self.executed_lines: deque[str] = deque(maxlen=1000)
        """The cleaned lines the controller ran, oldest first (for tests and logs)."""
        self.soft_resets_received = 0
        """Ctrl-X bytes the host sent (a driver should need none when the banner comes)."""

    # --- what the world sees -----------------------------------------------------------------

    @property
    def angle_deg(self) -> float:
        with self._lock:
            return self.motion.position_deg

    @property
    def state(self) -> str:
        """Grbl's state name as the status line shows it, e.g. ``Idle``, ``Hold:0``."""
        with self._lock:
            return self._state()

    @property
    def in_alarm(self) -> bool:
        with self._lock:
            return self._alarm_code is not None or self._critical

    def take_output(self) -> bytes:
        with self._lock:
            data = bytes(self._out)
            self._out.clear()
            return data

    # --- power, bytes in, time ----------------------------------------------------------------

    def power_on(self) -> None:
        """Power-up: banner; Alarm (locked) when homing is enabled, as Grbl's init lock.

        The model keeps the table angle (a real board restarts MPos at 0 where the table is).
        """
        with self._lock:
            self._clear_motion_and_input()
            self._alarm_code = None
            self._critical = False
            if self.settings[22]:
                self._alarm_code = 0
            self._announce_start()

    def receive(self, data: bytes) -> None:
        """Bytes from the host. Real-time bytes act at once, wherever they are in a line."""
        with self._lock:
            for byte in data:
                if self._silent:
                    continue
                if byte == p.SOFT_RESET[0]:
                    self.soft_resets_received += 1
                    self._soft_reset()
                elif byte == p.STATUS_QUERY[0] and self.motion.homing:
                    # Grbl's homing loop runs no real-time protocol: the queries are one
                    # report, sent when the cycle ends (limits.c)
                    self._report_after_homing = True
                elif byte == p.STATUS_QUERY[0]:
                    if not self._critical or self.status_in_critical_alarm:
                        self._emit(self._status_line())
                elif self._asleep:
                    continue  # asleep, the firmware reads no line and no hold, only ? and Ctrl-X
                elif byte == p.FEED_HOLD[0]:
                    self._feed_hold()
                elif byte == p.CYCLE_START[0]:
                    self._cycle_start()
                elif byte < 0x80:
                    self._rx.append(byte)
                    if byte in b"\r\n":
                        self._run_lines()

    def advance(self, dt_s: float) -> None:
        """Run model time by ``dt_s`` seconds; ``math.inf`` finishes all that can finish."""
        with self._lock:
            for _ in range(10_000 if math.isinf(dt_s) else 1):
                if self.motion.advance(dt_s):
                    self._raise_alarm(1, pin=True)
                if not self._end_wait(dt_s):
                    break
                self._run_lines()
            self._report_angle()

    # --- injectable faults ----------------------------------------------------------------

    def inject_stall(self, after_deg: float = 0.0) -> None:
        """The motor stalls after ``after_deg`` more degrees: hard limit, ALARM:1."""
        with self._lock:
            self.motion.inject_stall(after_deg)

    def inject_alarm(self, code: int) -> None:
        """An alarm now (motion stops at once). ALARM:1 and :2 lock until a reset."""
        with self._lock:
            self._raise_alarm(code, pin=code == 1)

    def set_silent(self, silent: bool) -> None:
        """A silent controller reads nothing and answers nothing (a hung board, a cut wire)."""
        with self._lock:
            self._silent = silent

    def garble(self, count: int = 1, skip: int = 0) -> None:
        """Corrupt the ``count`` output lines after the next ``skip`` ones (seeded noise)."""
        with self._lock:
            self._garble_skip, self._garble_count = skip, count

    # --- lines --------------------------------------------------------------------------

    def _run_lines(self) -> None:
        while self._wait is None and not self._critical and not self._asleep:
            ends = [i for i in (self._rx.find(b"\n"), self._rx.find(b"\r")) if i >= 0]
            if not ends:
                return
            end = min(ends)
            raw = bytes(self._rx[:end])
            del self._rx[: end + 1]
            self._execute(raw)

    def _execute(self, raw: bytes) -> None:
        text, overflow = clean_line(raw)
        self.executed_lines.append(text)
        if overflow:
            self._answer(11)
        elif not text:
            self._answer(0)
        elif text.startswith("$"):
            self._answer(self._system(text[1:]))
            if self._reset_after_answer:  # leaving check mode: ok, then the reset's banner
                self._reset_after_answer = False
                self._soft_reset()
            elif self._asleep:
                self._emit(p.format_reply(p.Message("Sleeping")))
        elif self._alarm_code is not None:
            self._answer(9)
        else:
            block = parse_block(text)
            self._answer(block if isinstance(block, int) else self._gcode(block))

    def _answer(self, code: int | None) -> None:
        """``ok`` (0), ``error:code``, or nothing yet (``None``: the line is still running)."""
        if code == 0:
            self._emit(p.format_reply(p.Ok()))
        elif code is not None:
            self._emit(p.format_reply(p.ErrorReply(code, error_meaning(code))))

    def _gcode(self, block: GBlock) -> int | None:
        modal = self._modal
        inches = block.codes.get("units", 20 if modal.inches else 21) == 20
        scale = 25.4 if inches else 1.0
        motion = block.codes.get("motion", modal.motion)
        feed = block.words["F"] * scale if "F" in block.words else modal.feed_per_min
        if block.axis_words and motion == 1 and feed <= 0.0:
            return 22
        modal.inches, modal.motion, modal.feed_per_min = inches, motion, feed
        modal.absolute = block.codes.get("distance", 90 if modal.absolute else 91) == 90
        move = self._plan_move(block, scale, motion, feed)
        if block.codes.get("stopping") in (2, 30):
            self._modal = _Modal()
            self._emit(p.format_reply(p.Message("Pgm End")))
        if block.codes.get("non_modal") == 4 and not self._check_mode:
            self._wait = _Wait("barrier", move, block.words["P"])
            return None
        return self._queue(move) if move else 0

    def _plan_move(self, block: GBlock, scale: float, motion: int, feed: float) -> MoveBlock | None:
        if "X" not in block.words:
            return None
        value_deg = block.words["X"] * scale
        absolute = self._modal.absolute or block.codes.get("non_modal") == 53
        target_deg = value_deg if absolute else self._planned_x_deg + value_deg
        rate_per_min = self.settings[110] if motion == 0 else min(feed, self.settings[110])
        self._planned_x_deg = target_deg
        return MoveBlock(target_deg, rate_per_min / 60.0)

    def _queue(self, move: MoveBlock) -> int | None:
        if self._check_mode:
            return 0  # parsed and answered; nothing moves
        if self.motion.full:
            self._wait = _Wait("planner", move)
            return None
        self.motion.push(move)
        return 0

    def _end_wait(self, dt_s: float) -> bool:
        """Finish the running line if it can finish now; True when it did."""
        wait = self._wait
        if wait is None or self._critical:
            return False
        if wait.kind == "planner" and not self.motion.full and wait.block is not None:
            self.motion.push(wait.block)
        elif wait.kind == "homing" and self.motion.idle:
            self._alarm_code = None
            if self._report_after_homing:
                self._report_after_homing = False
                self._emit(self._status_line())
        elif wait.kind == "barrier" and self.motion.idle:
            wait.dwell_s -= dt_s
            if wait.dwell_s > 0.0:
                return False
            if wait.block is not None:
                self.motion.push(wait.block)
        else:
            return False
        self._wait = None
        self._answer(0)
        return True

    # --- system commands ------------------------------------------------------------------

    def _system(self, command: str) -> int | None:
        if command == "":
            self._emit(p.format_reply(p.Feedback("HLP", HELP)))
        elif command in ("$", "G", "X"):
            return self._system_any_state(command)
        elif command == "C":
            return self._toggle_check_mode()
        elif command[:1] in ("$", "G", "X", "C", "J"):
            return 3
        elif self._state() not in ("Idle", "Alarm"):
            return 8
        elif command == "#":
            for name in ("G54", "G55", "G56", "G57", "G58", "G59", "G28", "G30", "G92"):
                self._emit(p.format_reply(p.Feedback(name, "0.000,0.000,0.000")))
            self._emit(p.format_reply(p.Feedback("TLO", "0.000")))
            self._emit(p.format_reply(p.Feedback("PRB", "0.000,0.000,0.000:0")))
        elif command == "H":
            return self._home()
        elif command == "I":
            self._emit(p.format_reply(p.Feedback("VER", f"{VERSION}.20190830:")))
            self._emit(p.format_reply(p.Feedback("OPT", "V,15,128")))
        elif command == "N":
            self._emit(b"$N0=\r\n$N1=\r\n")
        elif command == "SLP":
            self._asleep = True  # "ok", then the firmware's sleep message (_execute)
        elif command[:1] == "S":
            return 3
        else:
            return self._store_setting(command)
        return 0

    def _system_any_state(self, command: str) -> int:
        if command == "$":
            if self._state().partition(":")[0] in ("Run", "Hold", "Home"):
                return 8
            for number, value in self.settings.items():
                self._emit(p.format_setting(number, value, number in INTEGER_SETTINGS))
        elif command == "G":
            m = self._modal
            modes = f"G{m.motion} G54 G17 {'G20' if m.inches else 'G21'} "
            modes += f"{'G90' if m.absolute else 'G91'} G94 M5 M9 T0 F{m.feed_per_min:.0f} S0"
            self._emit(p.format_reply(p.Feedback("GC", modes)))
        elif self._alarm_code is not None:
            self._alarm_code = None
            self._limit_pin = False
            self._emit(p.format_reply(p.Message("Caution: Unlocked")))
        return 0

    def _store_setting(self, command: str) -> int:
        number_text, sep, value_text = command.partition("=")
        if not number_text.replace(".", "", 1).isdigit():
            return 2
        if not sep:
            return 3
        try:
            value = float(value_text)
        except ValueError:
            return 2
        try:
            check_setting(int(float(number_text)), value)
        except SettingsError as error:
            return error.code
        self.settings[int(float(number_text))] = value
        self.motion.accel_deg_s2 = self.settings[120]
        return 0

    def _toggle_check_mode(self) -> int:
        """``$C``: into check mode from Idle; out of it by a reset after the ``ok``."""
        if self._check_mode:
            self._emit(p.format_reply(p.Message("Disabled")))
            self._reset_after_answer = True
            return 0
        if self._state() != "Idle":
            return 8
        self._check_mode = True
        self._emit(p.format_reply(p.Message("Enabled")))
        return 0

    def _home(self) -> int | None:
        if not self.settings[22]:
            return 5
        rate_deg_s = self.settings[25] / 60.0
        self._alarm_code = None
        self.motion.push(MoveBlock(0.0, rate_deg_s, homing=True))
        self._planned_x_deg = 0.0
        self._wait = _Wait("homing")
        return None

    # --- real-time bytes, alarms, reset -------------------------------------------------------

    def _feed_hold(self) -> None:
        if self._alarm_code is None and not self._critical and not self._check_mode:
            self.motion.held = True

    def _cycle_start(self) -> None:
        if self.motion.held and self.motion.velocity_deg_s == 0.0:
            self.motion.held = False

    def _raise_alarm(self, code: int, *, pin: bool) -> None:
        self.motion.stop_now()
        self._planned_x_deg = self.motion.position_deg
        self._alarm_code = code
        self._limit_pin = self._limit_pin or pin
        self._emit(p.format_reply(p.AlarmReply(code, alarm_meaning(code))))
        if code in CRITICAL_ALARMS:
            self._critical = True
            self._emit(p.format_reply(p.Message("Reset to continue")))

    def _soft_reset(self) -> None:
        if not self.motion.idle and not self._critical:
            self._raise_alarm(6 if self.motion.homing else 3, pin=False)
        if self._wait is not None:
            self._answer(0)  # the interrupted line still reports, as the firmware does
        self._report_after_homing = False
        self._critical = False
        self._limit_pin = False
        self._check_mode = False
        if self._asleep:  # the steppers were off: Grbl comes up locked
            self._asleep = False
            self._alarm_code = 0
        self._clear_motion_and_input()
        self._announce_start()

    def _clear_motion_and_input(self) -> None:
        self.motion.stop_now()
        self._planned_x_deg = self.motion.position_deg
        self._rx.clear()
        self._wait = None
        self._modal = _Modal()
        self._wco_counter = self._ovr_counter = 0

    def _announce_start(self) -> None:
        self._emit(p.format_banner(VERSION))
        if self._alarm_code is not None:
            self._emit(p.format_reply(p.Message("'$H'|'$X' to unlock")))

    # --- output -----------------------------------------------------------------------------

    def _state(self) -> str:
        if self._asleep:
            return "Sleep"
        if self._alarm_code is not None or self._critical:
            return "Alarm"
        if self._check_mode:
            return "Check"
        if self.motion.held:
            return "Hold:1" if self.motion.velocity_deg_s > 0.0 else "Hold:0"
        if self.motion.homing:
            return "Home"
        return "Idle" if self.motion.idle else "Run"

    def _status_line(self) -> bytes:
        state, _, sub = self._state().partition(":")
        busy = state in ("Run", "Hold", "Home")
        x_deg = self.motion.position_deg
        wco: tuple[float, ...] | None = None
        other: dict[str, str] = {}
        if self._wco_counter > 0:
            self._wco_counter -= 1
        else:
            self._wco_counter = (30 if busy else 10) - 1
            self._ovr_counter = max(self._ovr_counter, 1)
            wco = (0.0, 0.0, 0.0)
        if self._ovr_counter > 0:
            self._ovr_counter -= 1
        else:
            self._ovr_counter = (20 if busy else 10) - 1
            other["Ov"] = "100,100,100"
        report = p.StatusReport(
            state=state,
            substate=int(sub) if sub else None,
            mpos=(x_deg, 0.0, 0.0) if int(self.settings[10]) & 1 else None,
            wpos=None if int(self.settings[10]) & 1 else (x_deg, 0.0, 0.0),
            wco=wco,
            feed=self.motion.velocity_deg_s * 60.0,
            spindle=0.0,
            pins="X" if self._limit_pin else "",
            other=other,
        )
        return p.format_status(report)

    def _emit(self, data: bytes) -> None:
        """Queue controller output line by line, applying the silence and garble faults."""
        if self._silent:
            return
        for line in data.split(b"\r\n")[:-1]:
            if line and self._garble_skip > 0:
                self._garble_skip -= 1
            elif line and self._garble_count > 0:
                self._garble_count -= 1
                line = self._corrupt(line)
            self._out.extend(line + b"\r\n")

    def _corrupt(self, line: bytes) -> bytes:
        noisy = bytearray(line)
        positions = [i for i in range(len(noisy)) if self._rng.random() < 0.3]
        for i in positions or [self._rng.randrange(len(noisy))]:
            noisy[i] |= 0x80
        return bytes(noisy)

    def _settle_offset(self) -> float:
        if self._off_target_deg == 0.0:
            return 0.0
        return self._rng.uniform(-self._off_target_deg, self._off_target_deg)

    def _report_angle(self) -> None:
        angle_deg = self.motion.position_deg
        if angle_deg != self._last_angle_deg and self.on_angle is not None:
            try:
                self.on_angle(angle_deg)
            except Exception:
                log.exception("on_angle callback failed")
        self._last_angle_deg = angle_deg
