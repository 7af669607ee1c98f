"""Byte-level tests of the Grbl 1.1 protocol module: (received bytes, parsed value) tables."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from devices.table import protocol as p
from devices.table.codes import ALARM_MEANINGS, ERROR_MEANINGS, alarm_meaning, error_meaning

RECEIVED = [
    (b"ok", p.Ok()),
    (b"error:1", p.ErrorReply(1, ERROR_MEANINGS[1])),
    (b"error:9", p.ErrorReply(9, ERROR_MEANINGS[9])),
    (b"error:22", p.ErrorReply(22, ERROR_MEANINGS[22])),
    (b"error:99", p.ErrorReply(99, "unknown error code 99")),
    (b"ALARM:1", p.AlarmReply(1, ALARM_MEANINGS[1])),
    (b"ALARM:3", p.AlarmReply(3, ALARM_MEANINGS[3])),
    (b"Grbl 1.1h ['$' for help]", p.Banner("1.1h")),
    (b"Grbl 1.1f ['$' for help]", p.Banner("1.1f")),
    (b"GrblHAL 1.1f ['$' or '$HELP' for help]", p.Banner("1.1f")),  # grblHAL's default
    (b"[MSG:Reset to continue]", p.Message("Reset to continue")),
    (b"[MSG:'$H'|'$X' to unlock]", p.Message("'$H'|'$X' to unlock")),
    (b"[MSG:Caution: Unlocked]", p.Message("Caution: Unlocked")),
    (b"[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]",
     p.Feedback("GC", "G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0")),
    (b"[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]",
     p.Feedback("HLP", "$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x")),
    (b"[VER:1.1h.20190830:]", p.Feedback("VER", "1.1h.20190830:")),
    (b"[OPT:V,15,128]", p.Feedback("OPT", "V,15,128")),
    (b"[G54:0.000,0.000,0.000]", p.Feedback("G54", "0.000,0.000,0.000")),
    (b"[PRB:0.000,0.000,0.000:0]", p.Feedback("PRB", "0.000,0.000,0.000:0")),
    (b"[echo:G0X1]", p.Feedback("echo", "G0X1")),
    (b"$100=1600.000", p.SettingLine(100, 1600.0)),
    (b"$0=10", p.SettingLine(0, 10.0)),
    (b"$N0=", p.StartupLine("$N0=")),
    (b">G20G54:ok", p.StartupLine(">G20G54:ok")),
]  # fmt: skip

GARBLED = [
    b"o\xeb",
    b"ok ",
    b"OK",
    b"error:",
    b"error:x",
    b"ALARM:1\xb1",
    b"Grbl 1.1h",
    b"<Idle|MPos:1.000,2.000,3.000",
    b"<Idle|MPos:4\xb5.000,0.000,0.000|FS:0,0>",
    b"<Idle|MPos:abc|FS:0,0>",
    b"<Idle|FS:0,0>",
    b"<Idle|MPos:0,0,0|WPos:0,0,0>",
    b"<Walk|MPos:0.000,0.000,0.000>",
    b"<Hold:x|MPos:0.000,0.000,0.000>",
    b"<Idle|MPos0.000>",
    b"\x00ok",
    b"random noise",
]


@pytest.mark.parametrize(("received", "expected"), RECEIVED)
def test_parse_every_kind_of_line(received: bytes, expected: p.Reply) -> None:
    assert p.parse_line(received) == expected


@pytest.mark.parametrize("received", GARBLED)
def test_invalid_lines_are_garbled_never_ok_or_position(received: bytes) -> None:
    assert p.parse_line(received) == p.Garbled(received)


STATUS = [
    (b"<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>",
     "Idle", None, 0.0, 0.0, (0.0, 0.0, 0.0), "", {}),
    (b"<Run|MPos:12.345,0.000,0.000|FS:720,0|Ov:100,100,100>",
     "Run", None, 12.345, 720.0, None, "", {"Ov": "100,100,100"}),
    (b"<Hold:1|MPos:-3.500,0.000,0.000|Bf:15,128|FS:120,0|Pn:XYZ>",
     "Hold", 1, -3.5, 120.0, None, "XYZ", {"Bf": "15,128"}),
    (b"<Alarm|MPos:10.000,0.000,0.000|FS:0,0|Pn:X|A:SFM>",
     "Alarm", None, 10.0, 0.0, None, "X", {"A": "SFM"}),
    (b"<Door:2|MPos:1.000,2.000,3.000|F:500|Ln:99>",
     "Door", 2, 1.0, 500.0, None, "", {"Ln": "99"}),
    (b"<Home|MPos:0.000,0.000,0.000|FS:0,0>", "Home", None, 0.0, 0.0, None, "", {}),
    (b"<Check|MPos:0.000,0.000,0.000|FS:0,0>", "Check", None, 0.0, 0.0, None, "", {}),
]  # fmt: skip


@pytest.mark.parametrize(
    ("received", "state", "sub", "x_deg", "feed", "wco", "pins", "other"), STATUS
)
def test_status_fields_known_and_unknown(
    received: bytes,
    state: str,
    sub: int | None,
    x_deg: float,
    feed: float,
    wco: tuple[float, ...] | None,
    pins: str,
    other: dict[str, str],
) -> None:
    report = p.parse_line(received)
    assert isinstance(report, p.StatusReport)
    assert (report.state, report.substate, report.feed, report.wco) == (state, sub, feed, wco)
    assert (report.pins, report.other) == (pins, other)
    assert report.machine_x_deg(wco_x_deg=0.0) == pytest.approx(x_deg, abs=1e-9)


def test_wpos_report_is_shifted_by_the_work_offset() -> None:
    report = p.parse_line(b"<Idle|WPos:40.000,0.000,0.000|FS:0,0|WCO:5.000,0.000,0.000>")
    assert isinstance(report, p.StatusReport)
    assert report.mpos is None
    assert report.machine_x_deg(wco_x_deg=5.0) == pytest.approx(45.0)


SENT = [
    ("G21 G90 G0 X45.0000", b"G21 G90 G0 X45.0000\n"),
    ("G4 P0", b"G4 P0\n"),
    ("$X", b"$X\n"),
    ("$H", b"$H\n"),
    ("X" * 79, b"X" * 79 + b"\n"),
]


@pytest.mark.parametrize(("command", "sent"), SENT)
def test_encode_lines(command: str, sent: bytes) -> None:
    assert p.encode_line(command) == sent


@pytest.mark.parametrize("command", ["X" * 80, "G0 X1?", "G0 X1\nG0 X2", "G0 X1!", "G0 X°"])
def test_encode_refuses_what_grbl_would_mangle(command: str) -> None:
    with pytest.raises(p.ProtocolError):
        p.encode_line(command)


@pytest.mark.parametrize(
    ("target_deg", "line"),
    [
        (45.0, "G21 G90 G0 X45.0000"),
        (-0.5, "G21 G90 G0 X-0.5000"),
        (359.99995, "G21 G90 G0 X360.0000"),
    ],
)
def test_goto_line(target_deg: float, line: str) -> None:
    assert p.goto_line(target_deg) == line


@pytest.mark.parametrize("target_deg", [float("nan"), float("inf"), 1e7])
def test_goto_line_refuses_unusable_angles(target_deg: float) -> None:
    with pytest.raises(p.ProtocolError, match="target angle"):
        p.goto_line(target_deg)


@given(
    x_deg=st.floats(-1e5, 1e5, allow_nan=False),
    state=st.sampled_from(["Idle", "Run", "Alarm", "Home"]),
    feed=st.integers(0, 10000),
    pins=st.sampled_from(["", "X", "XYZ"]),
)
def test_formatted_status_parses_back(x_deg: float, state: str, feed: int, pins: str) -> None:
    report = p.StatusReport(state, None, (x_deg, 0.0, 0.0), None, None, float(feed), 0.0, pins)
    parsed = p.parse_line(p.format_status(report).rstrip(b"\r\n"))
    assert isinstance(parsed, p.StatusReport)
    assert parsed.machine_x_deg(0.0) == pytest.approx(x_deg, abs=5e-4)
    assert (parsed.state, parsed.feed, parsed.pins) == (state, feed, pins)


@given(
    lines=st.lists(st.sampled_from([b"ok", b"error:9", b"<Idle|MPos:1.000,0,0>", b"[MSG:x]"])),
    cuts=st.lists(st.integers(0, 400), max_size=6),
)
def test_line_splitter_is_independent_of_chunking(lines: list[bytes], cuts: list[int]) -> None:
    stream = b"".join(line + b"\r\n" for line in lines)
    bounds = [0, *sorted(c for c in cuts if c <= len(stream)), len(stream)]
    splitter = p.LineSplitter()
    out: list[bytes] = []
    for start, end in itertools.pairwise(bounds):
        out += splitter.feed(stream[start:end])
    assert out == lines


def test_line_splitter_drops_blank_lines_and_bounds_noise() -> None:
    splitter = p.LineSplitter(max_line_bytes=16)
    assert splitter.feed(b"\r\nGrbl 1.1h ['$' for help]\r\n") == [b"Grbl 1.1h ['$' for help]"]
    assert splitter.feed(b"\xff" * 20) == [b"\xff" * 20]
    assert splitter.feed(b"ok\n") == [b"ok"]


def test_code_tables_cover_grbl_1_1() -> None:
    assert sorted(ERROR_MEANINGS) == [*range(1, 18), *range(20, 39)]
    assert sorted(ALARM_MEANINGS) == list(range(1, 11))  # 10: dual-axis homing (1.1f on)
    assert "lock" in error_meaning(9)
    assert "hard limit" in alarm_meaning(1)
    assert alarm_meaning(42) == "unknown alarm code 42"


def test_grblhal_status_lines_are_read() -> None:
    """grblHAL (the 32-bit successor) adds a ``Tool`` state (a tool change waiting) and flags
    without a value (``|AR``): read, not taken for line noise."""
    report = p.parse_status(b"<Tool|MPos:1.000,0.000,0.000|FS:0,0|AR>")
    assert isinstance(report, p.StatusReport)
    assert (report.state, report.mpos) == ("Tool", (1.0, 0.0, 0.0))
    assert isinstance(p.parse_status(b"<Idle|MPos:1.000,0.000,0.000|F#S>"), p.Garbled)
