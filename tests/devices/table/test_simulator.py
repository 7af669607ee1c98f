"""The simulated controller answers like Grbl 1.1: tables of (sent, received) bytes."""

from __future__ import annotations

import math
import random

import pytest

from devices.table import GrblSimulator
from devices.table import protocol as p

BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"


def powered(**kwargs: object) -> GrblSimulator:
    sim = GrblSimulator(**kwargs)  # type: ignore[arg-type]
    sim.power_on()
    assert sim.take_output() == BANNER
    return sim


def exchange(sim: GrblSimulator, sent: bytes, dt_s: float = math.inf) -> bytes:
    sim.receive(sent)
    sim.advance(dt_s)
    return sim.take_output()


LINES = [
    (b"G0 X10\n", b"ok\r\n"),
    (b"g0x10\n", b"ok\r\n"),
    (b"\n", b"ok\r\n"),
    (b"(just a comment)\n", b"ok\r\n"),
    (b"G0 X1 ; trailing comment\n", b"ok\r\n"),
    (b"1\n", b"error:1\r\n"),
    (b"HELLO\n", b"error:2\r\n"),
    (b"G0 X\n", b"error:2\r\n"),
    (b"G5 X1\n", b"error:20\r\n"),
    (b"Q1\n", b"error:20\r\n"),
    (b"G0 G1 X1\n", b"error:21\r\n"),
    (b"G0.5 X1\n", b"error:23\r\n"),
    (b"X1 X2\n", b"error:25\r\n"),
    (b"G1 X5\n", b"error:22\r\n"),
    (b"G1 X5 F-3\n", b"error:4\r\n"),
    (b"G4\n", b"error:28\r\n"),
    (b"G4 P-1\n", b"error:4\r\n"),
    (b"P1\n", b"error:36\r\n"),
    (b"G0 X" + b"1" * 80 + b"\n", b"error:11\r\n"),
    (b"G0 X" + b"0" * 76 + b"\n", b"ok\r\n"),  # 79 characters fit (protocol.c), 80 do not:
    (b"G0 X" + b"0" * 77 + b"\n", b"error:11\r\n"),
    (b"$Q\n", b"error:2\r\n"),
    (b"$$x\n", b"error:3\r\n"),
    (b"$100\n", b"error:3\r\n"),
    (b"$999=1\n", b"error:3\r\n"),
    (b"$100=-5\n", b"error:4\r\n"),
    (b"$H\n", b"error:5\r\n"),
    (b"$X\n", b"ok\r\n"),
    (b"$\n", b"[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]\r\nok\r\n"),
    (b"$G\n", b"[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]\r\nok\r\n"),
    (b"$I\n", b"[VER:1.1h.20190830:]\r\n[OPT:V,15,128]\r\nok\r\n"),
    (b"$N\n", b"$N0=\r\n$N1=\r\nok\r\n"),
    (b"M3 S100\n", b"ok\r\n"),
    (b"M30\n", b"[MSG:Pgm End]\r\nok\r\n"),
    (b"G4 P0\n", b"ok\r\n"),
    (b"G0 X1\nG0 X2\n", b"ok\r\nok\r\n"),
]  # fmt: skip


@pytest.mark.parametrize(("sent", "received"), LINES)
def test_ok_and_error_rules(sent: bytes, received: bytes) -> None:
    assert exchange(powered(), sent) == received


def test_status_line_format_and_refresh_counters() -> None:
    sim = powered()
    assert exchange(sim, b"?") == b"<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>\r\n"
    assert exchange(sim, b"?") == b"<Idle|MPos:0.000,0.000,0.000|FS:0,0|Ov:100,100,100>\r\n"
    assert exchange(sim, b"?") == b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"
    sim.receive(b"$10=0\n")
    assert sim.take_output() == b"ok\r\n"
    assert exchange(sim, b"G0 X12.5\n?") == b"ok\r\n<Run|WPos:0.000,0.000,0.000|FS:0,0>\r\n"
    assert exchange(sim, b"?") == b"<Idle|WPos:12.500,0.000,0.000|FS:0,0>\r\n"


def test_settings_report_has_the_table_values() -> None:
    out = exchange(powered(), b"$$\n").decode()
    lines = out.split("\r\n")
    assert "$100=1600.000" in lines  # 200 steps x 16 microsteps x 180:1 / 360 deg
    assert "$110=720.000" in lines
    assert "$120=30.000" in lines
    assert "$22=0" in lines
    assert lines[-2:] == ["ok", ""]


def test_g4_answers_only_when_the_motion_buffer_is_empty() -> None:
    sim = powered()
    # trapezoid ground truth: v = 720/60 = 12 deg/s, a = 30 deg/s^2, 45 deg
    travel_s = 45.0 / 12.0 + 12.0 / 30.0
    assert exchange(sim, b"G0 X45\nG4 P0\n", dt_s=0.0) == b"ok\r\n"
    assert exchange(sim, b"?", dt_s=travel_s - 0.05).startswith(b"<Run|MPos:0.000")
    assert sim.state == "Run"
    assert 44.0 < sim.angle_deg < 45.0
    assert exchange(sim, b"", dt_s=0.1) == b"ok\r\n"
    assert sim.state == "Idle"
    assert sim.angle_deg == pytest.approx(45.0, abs=1e-9)


def test_dwell_waits_its_seconds() -> None:
    sim = powered()
    assert exchange(sim, b"G4 P0.5\n", dt_s=0.4) == b""
    assert exchange(sim, b"", dt_s=0.2) == b"ok\r\n"


def test_realtime_bytes_act_mid_line() -> None:
    sim = powered()
    out = exchange(sim, b"G0 X1?0\n")
    assert out.startswith(b"<Idle|MPos:0.000")
    assert out.endswith(b"ok\r\n")
    assert sim.angle_deg == pytest.approx(10.0)
    out = exchange(sim, b"G0 X5\x18\n")
    assert out == BANNER + b"ok\r\n"  # the half line died with the reset; "\n" is a blank line
    assert sim.angle_deg == pytest.approx(10.0)


def test_feed_hold_and_resume() -> None:
    sim = powered()
    exchange(sim, b"G0 X45\n", dt_s=2.0)
    moving_deg = sim.angle_deg
    sim.receive(b"!")
    assert sim.state == "Hold:1"
    sim.advance(1.0)
    assert sim.state == "Hold:0"
    braking_deg = 12.0**2 / (2 * 30.0)
    assert moving_deg < sim.angle_deg <= moving_deg + braking_deg + 0.01
    held_deg = sim.angle_deg
    sim.advance(5.0)
    assert sim.angle_deg == held_deg
    sim.receive(b"~")
    sim.advance(10.0)
    assert (sim.state, sim.angle_deg) == ("Idle", pytest.approx(45.0))


def test_hold_when_idle_is_hold_complete() -> None:
    sim = powered()
    assert exchange(sim, b"!?").startswith(b"<Hold:0|")
    assert exchange(sim, b"~?").startswith(b"<Idle|")


def test_planner_buffer_delays_the_ok_when_full() -> None:
    sim = powered()
    out = exchange(sim, b"G91 G0 X1\n" * 20, dt_s=0.0)
    assert out == b"ok\r\n" * 15
    out = exchange(sim, b"", dt_s=math.inf)
    assert out == b"ok\r\n" * 5
    assert sim.angle_deg == pytest.approx(20.0)


def test_stall_is_a_hard_limit_alarm_that_locks_until_reset() -> None:
    sim = powered()
    sim.inject_stall(after_deg=7.0)
    out = exchange(sim, b"G0 X45\nG4 P0\n")
    assert out == b"ok\r\nALARM:1\r\n[MSG:Reset to continue]\r\n"
    assert sim.angle_deg == pytest.approx(7.0)
    assert exchange(sim, b"$X\nG0 X1\n") == b""  # everything but Ctrl-X is ignored,
    assert exchange(sim, b"?") == b""  # ? too in Grbl 1.1h (protocol.c's critical loop)
    sim.status_in_critical_alarm = True  # grblHAL answers it
    assert exchange(sim, b"?").startswith(b"<Alarm|MPos:7.000,0.000,0.000|FS:0,0|Pn:X")
    out = exchange(sim, b"\x18")
    assert out == b"ok\r\n" + BANNER + b"[MSG:'$H'|'$X' to unlock]\r\n"
    assert exchange(sim, b"G0 X1\n") == b"error:9\r\n"
    assert exchange(sim, b"$X\n") == b"[MSG:Caution: Unlocked]\r\nok\r\n"
    assert exchange(sim, b"G0 X1\n") == b"ok\r\n"


def test_reset_while_moving_raises_alarm_3() -> None:
    sim = powered()
    exchange(sim, b"G0 X45\nG4 P0\n", dt_s=1.0)
    out = exchange(sim, b"\x18", dt_s=0.0)
    assert out == b"ALARM:3\r\nok\r\n" + BANNER + b"[MSG:'$H'|'$X' to unlock]\r\n"
    assert sim.state == "Alarm"
    assert 0.0 < sim.angle_deg < 45.0


def test_homing_when_enabled_starts_locked_and_homes_to_zero() -> None:
    sim = GrblSimulator(settings={22: 1})
    sim.power_on()
    assert sim.take_output() == BANNER + b"[MSG:'$H'|'$X' to unlock]\r\n"
    assert exchange(sim, b"G0 X5\n") == b"error:9\r\n"
    assert exchange(sim, b"$H\n") == b"ok\r\n"
    assert (sim.state, sim.angle_deg) == ("Idle", 0.0)


def test_check_mode_answers_moves_without_turning_and_leaves_by_a_reset() -> None:
    """As the Grbl 1.1h firmware does (the byte-for-byte test of ``test_grbl_firmware.py``)."""
    sim = powered()
    assert exchange(sim, b"$C x\n") == b"error:3\r\n"
    assert exchange(sim, b"$C\n") == b"[MSG:Enabled]\r\nok\r\n"
    assert exchange(sim, b"G0 X20\nG4 P0\n") == b"ok\r\nok\r\n"
    assert (sim.state, sim.angle_deg) == ("Check", 0.0)
    assert exchange(sim, b"!") == b""  # a feed hold does nothing in check mode
    assert exchange(sim, b"$H\n$SLP\n$X\n") == b"error:8\r\nerror:8\r\nok\r\n"
    assert exchange(sim, b"$C\n") == b"[MSG:Disabled]\r\nok\r\n" + BANNER
    assert sim.state == "Idle"
    exchange(sim, b"G0 X20\nG4 P0\n")
    assert sim.angle_deg == pytest.approx(20.0)
    exchange(sim, b"!")
    assert exchange(sim, b"$C\n") == b"error:8\r\n"  # from Idle only (here Hold:0)


def test_sleep_reads_nothing_but_status_and_reset_and_wakes_locked() -> None:
    sim = powered()
    assert exchange(sim, b"$SLP\n") == b"ok\r\n[MSG:Sleeping]\r\n"
    assert sim.state == "Sleep"
    assert exchange(sim, b"G0 X10\n$X\n!~") == b""  # dropped: no answer at all
    assert exchange(sim, b"?").startswith(b"<Sleep|MPos:0.000,")
    assert exchange(sim, b"\x18") == BANNER + b"[MSG:'$H'|'$X' to unlock]\r\n"
    assert sim.state == "Alarm"
    assert exchange(sim, b"$X\nG0 X10\n") == b"[MSG:Caution: Unlocked]\r\nok\r\nok\r\n"
    assert sim.angle_deg == pytest.approx(10.0)


def test_silence_and_garbled_bytes() -> None:
    sim = powered(seed=3)
    sim.set_silent(True)
    assert exchange(sim, b"G0 X5\n?") == b""
    assert sim.angle_deg == 0.0  # a silent controller does not read either
    sim.set_silent(False)
    sim.garble(count=2, skip=1)
    out = exchange(sim, b"G0 X5\nG0 X6\nG0 X7\n?")
    lines = p.LineSplitter().feed(out)
    assert len(lines) == 4
    parsed = [p.parse_line(line) for line in lines]
    assert parsed[0] == p.Ok()
    assert all(isinstance(reply, p.Garbled) for reply in parsed[1:3])
    assert isinstance(parsed[3], p.StatusReport)


def test_off_target_stops_are_seeded_and_bounded() -> None:
    def stops(seed: int) -> list[float]:
        sim = powered(off_target_deg=0.05, seed=seed)
        result = []
        for target in (45, 90, 135, 180):
            exchange(sim, f"G0 X{target}\n".encode())
            result.append(sim.angle_deg - target)
        return result

    errors = stops(seed=7)
    assert errors == stops(seed=7)
    assert errors != stops(seed=8)
    rng = random.Random(7)
    assert errors == pytest.approx([rng.uniform(-0.05, 0.05) for _ in range(4)])
    assert all(0.0 < abs(e) <= 0.05 for e in errors)


def test_on_angle_follows_the_table() -> None:
    seen: list[float] = []
    sim = powered(on_angle=seen.append)
    sim.receive(b"G0 X20\n")
    for _ in range(40):
        sim.advance(0.1)
    assert seen == sorted(seen)
    assert seen[-1] == pytest.approx(20.0)
    assert len(seen) > 10
