"""Grbl 1.1 wire protocol for the rotary table: bytes in, bytes out, no I/O.

Every line a Grbl 1.1 controller can send parses into one :data:`Reply` value; a line that is
not valid Grbl (noise, a corrupted byte) parses into :class:`Garbled`, never into something
that could be mistaken for ``ok`` or a position. The table is Grbl's X axis, in degrees.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from devices.table.codes import alarm_meaning, error_meaning

STATUS_QUERY = b"?"
FEED_HOLD = b"!"
CYCLE_START = b"~"
SOFT_RESET = b"\x18"
REALTIME_BYTES = frozenset(b"?!~\x18")

MAX_LINE_BYTES = 80
"""A command line including its newline never exceeds this (Grbl's line buffer)."""

BARRIER_LINE = "G4 P0"
UNLOCK_LINE = "$X"
HOME_LINE = "$H"
SETTINGS_LINE = "$$"
PARSER_STATE_LINE = "$G"

STATES = ("Idle", "Run", "Hold", "Jog", "Alarm", "Door", "Check", "Home", "Sleep", "Tool")
"""Grbl 1.1's states, and grblHAL's ``Tool`` (a tool change waiting: the driver moves only
from Idle)."""


class ProtocolError(ValueError):
    """A command cannot be encoded (too long, not ASCII, contains a real-time byte)."""


@dataclass(frozen=True)
class Ok:
    """``ok``: the oldest unanswered line ran (or was queued)."""


@dataclass(frozen=True)
class ErrorReply:
    """``error:N``: the oldest unanswered line could not run."""

    code: int
    meaning: str


@dataclass(frozen=True)
class AlarmReply:
    """``ALARM:N``: may arrive at any time; the controller is now in Alarm."""

    code: int
    meaning: str


@dataclass(frozen=True)
class Banner:
    """The start-up line ``Grbl 1.1h ['$' for help]`` (after power-up or a reset)."""

    version: str


@dataclass(frozen=True)
class Message:
    """A feedback message ``[MSG:text]``."""

    text: str


@dataclass(frozen=True)
class Feedback:
    """Any other bracketed line: ``[GC:...]``, ``[HLP:...]``, ``[VER:...]``, ``[G54:...]``..."""

    tag: str
    text: str


@dataclass(frozen=True)
class SettingLine:
    """A ``$N=value`` line of the ``$$`` report."""

    number: int
    value: float


@dataclass(frozen=True)
class StartupLine:
    """A ``$Nx=block`` stored start-up block or a ``>block:ok`` start-up execution echo."""

    text: str


@dataclass(frozen=True)
class StatusReport:
    """``<State|MPos:x,y,z|...>``; positions are per axis, the table is axis 0 (X, degrees).

    Exactly one of ``mpos`` and ``wpos`` is set (``$10`` chooses). ``wco`` is present only in
    the reports that carry it. Fields this driver does not use are kept in ``other``.
    """

    state: str
    substate: int | None
    mpos: tuple[float, ...] | None
    wpos: tuple[float, ...] | None
    wco: tuple[float, ...] | None = None
    feed: float | None = None
    spindle: float | None = None
    pins: str = ""
    other: dict[str, str] = field(default_factory=dict)

    def machine_x_deg(self, wco_x_deg: float) -> float:
        """Machine X in degrees; a WPos report is shifted by ``wco_x_deg`` (MPos = WPos + WCO)."""
        if self.mpos is not None:
            return self.mpos[0]
        if self.wpos is not None:
            return self.wpos[0] + wco_x_deg
        raise ValueError("status report carries neither MPos nor WPos")


@dataclass(frozen=True)
class Garbled:
    """A line that is not valid Grbl output (noise, corrupted bytes)."""

    raw: bytes


Reply = (
    Ok
    | ErrorReply
    | AlarmReply
    | Banner
    | Message
    | Feedback
    | SettingLine
    | StartupLine
    | StatusReport
    | Garbled
)

_BANNER = re.compile(r"Grbl(?:HAL)? (\d+\.\d+[a-z]?) \['\$' (?:or '\$HELP' )?for help\]")
"""Grbl 1.1's ``Grbl 1.1h ['$' for help]``, and grblHAL's ``GrblHAL 1.1f ['$' or '$HELP' for
help]`` (the 32-bit successor, same protocol)."""
_CODE = re.compile(r"(error|ALARM):(\d{1,3})")
_SETTING = re.compile(r"\$(\d{1,3})=(-?\d+(?:\.\d*)?)")
_STARTUP = re.compile(r"(\$N\d=.*|>.*:(ok|error:\d+))")
_BRACKET = re.compile(r"\[([A-Za-z0-9]+):(.*)\]")
_NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def parse_line(raw: bytes) -> Reply:
    """Parse one line (terminator already removed) sent by the controller."""
    if not raw or any(b < 0x20 or b > 0x7E for b in raw):
        return Garbled(raw)
    text = raw.decode("ascii")
    if text == "ok":
        return Ok()
    if match := _CODE.fullmatch(text):
        code = int(match.group(2))
        if match.group(1) == "error":
            return ErrorReply(code, error_meaning(code))
        return AlarmReply(code, alarm_meaning(code))
    if text.startswith("<"):
        return parse_status(raw)
    if match := _BANNER.fullmatch(text):
        return Banner(match.group(1))
    if match := _BRACKET.fullmatch(text):
        tag, body = match.group(1), match.group(2)
        return Message(body) if tag == "MSG" else Feedback(tag, body)
    if match := _SETTING.fullmatch(text):
        return SettingLine(int(match.group(1)), float(match.group(2)))
    if _STARTUP.fullmatch(text):
        return StartupLine(text)
    return Garbled(raw)


def _numbers(text: str) -> tuple[float, ...] | None:
    parts = text.split(",")
    if not all(_NUMBER.fullmatch(p) for p in parts):
        return None
    return tuple(float(p) for p in parts)


def parse_status(raw: bytes) -> StatusReport | Garbled:
    """Parse ``<State[:n]|MPos:..|...>``; malformed known fields make the line Garbled."""
    text = raw.decode("ascii", errors="replace")
    if not (text.startswith("<") and text.endswith(">")):
        return Garbled(raw)
    head, *fields = text[1:-1].split("|")
    state, _, sub = head.partition(":")
    if state not in STATES or (sub and not sub.isdigit()):
        return Garbled(raw)
    values: dict[str, tuple[float, ...]] = {}
    other: dict[str, str] = {}
    for item in fields:
        name, sep, body = item.partition(":")
        if not sep and not name.isalpha():  # grblHAL sends a flag or two without a value
            return Garbled(raw)
        if name in ("MPos", "WPos", "WCO", "FS", "F"):
            numbers = _numbers(body)
            if numbers is None:
                return Garbled(raw)
            values[name] = numbers
        else:
            other[name] = body
    if ("MPos" in values) == ("WPos" in values):
        return Garbled(raw)
    feed_speed = values.get("FS", values.get("F", ()))
    return StatusReport(
        state=state,
        substate=int(sub) if sub else None,
        mpos=values.get("MPos"),
        wpos=values.get("WPos"),
        wco=values.get("WCO"),
        feed=feed_speed[0] if len(feed_speed) > 0 else None,
        spindle=feed_speed[1] if len(feed_speed) > 1 else None,
        pins=other.pop("Pn", ""),
        other=other,
    )


class LineSplitter:
    """Cuts a byte stream into lines at ``\\n`` (dropping ``\\r`` and empty lines).

    A run of more than ``max_line_bytes`` bytes without a newline is emitted as one line (it
    will parse as Garbled) so noise can never grow the buffer without bound.
    """

    def __init__(self, max_line_bytes: int = 256) -> None:
        self._buffer = bytearray()
        self._max = max_line_bytes

    def feed(self, data: bytes) -> list[bytes]:
        """Add received bytes; return the complete lines they finish."""
        self._buffer.extend(data)
        lines: list[bytes] = []
        while True:
            end = self._buffer.find(b"\n")
            if end < 0:
                if len(self._buffer) > self._max:
                    lines.append(bytes(self._buffer))
                    self._buffer.clear()
                break
            line = bytes(self._buffer[:end]).strip(b"\r")
            del self._buffer[: end + 1]
            if line:
                lines.append(line)
        return lines

    def clear(self) -> None:
        self._buffer.clear()


def encode_line(text: str) -> bytes:
    """One command line as bytes (``text`` + ``\\n``); refuses what Grbl would mangle."""
    if not text.isascii() or any(ch in text for ch in "\r\n?!~\x18"):
        raise ProtocolError(f"command {text!r} must be one ASCII line without ? ! ~ or Ctrl-X")
    data = text.encode("ascii") + b"\n"
    if len(data) > MAX_LINE_BYTES:
        raise ProtocolError(f"command {text!r} is longer than {MAX_LINE_BYTES - 1} characters")
    return data


def goto_line(target_deg: float) -> str:
    """The absolute rapid move to ``target_deg`` on the X (table) axis, in millimetre mode
    (degrees here): a ``G20`` left by a startup block (``$N0``) would read X45 as 45 inches."""
    if target_deg != target_deg or abs(target_deg) > 1e6:
        raise ProtocolError(f"target angle {target_deg!r} deg is not a usable number")
    return f"G21 G90 G0 X{target_deg:.4f}"


# --- what a controller sends (used by the simulator, and by tests as ground truth) ----------


def format_axes(values: tuple[float, ...]) -> str:
    return ",".join(f"{v:.3f}" for v in values)


def format_status(report: StatusReport) -> bytes:
    """The status line of ``report`` exactly as Grbl 1.1 prints it (with ``\\r\\n``)."""
    head = report.state if report.substate is None else f"{report.state}:{report.substate}"
    parts = [head]
    if report.mpos is not None:
        parts.append(f"MPos:{format_axes(report.mpos)}")
    if report.wpos is not None:
        parts.append(f"WPos:{format_axes(report.wpos)}")
    early = ("Bf", "Ln")
    parts.extend(f"{name}:{report.other[name]}" for name in early if name in report.other)
    parts.append(f"FS:{report.feed or 0:.0f},{report.spindle or 0:.0f}")
    if report.pins:
        parts.append(f"Pn:{report.pins}")
    if report.wco is not None:
        parts.append(f"WCO:{format_axes(report.wco)}")
    parts.extend(f"{name}:{body}" for name, body in report.other.items() if name not in early)
    return ("<" + "|".join(parts) + ">\r\n").encode("ascii")


def format_banner(version: str = "1.1h") -> bytes:
    return f"\r\nGrbl {version} ['$' for help]\r\n".encode("ascii")


def format_reply(reply: Ok | ErrorReply | AlarmReply | Message | Feedback) -> bytes:
    if isinstance(reply, Ok):
        text = "ok"
    elif isinstance(reply, ErrorReply):
        text = f"error:{reply.code}"
    elif isinstance(reply, AlarmReply):
        text = f"ALARM:{reply.code}"
    elif isinstance(reply, Message):
        text = f"[MSG:{reply.text}]"
    else:
        text = f"[{reply.tag}:{reply.text}]"
    return (text + "\r\n").encode("ascii")


def format_setting(number: int, value: float, integer: bool) -> bytes:
    body = f"{int(value)}" if integer else f"{value:.3f}"
    return f"${number}={body}\r\n".encode("ascii")
