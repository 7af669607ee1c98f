"""The driver, unchanged, against the real Grbl 1.1h firmware (grbl-sim) on a pty.

Skipped unless ``GRBL_SIM_EXE`` names a grbl-sim executable (docs/TABLE.md: how to build one).
Moves run in real time at grbl-sim's settings with a faster rate and acceleration written to
its EEPROM by the test, so each module run takes about a minute.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial

from devices.table import (
    GrblTable,
    TableAlarm,
    TableDisconnected,
    TableError,
    TableHeld,
    TableReset,
    TableTimeout,
    TableTimeouts,
)

from .conftest import goto_in_background
from .firmware import GRBL_SIM_ENV, FirmwarePty, grbl_sim_executable

EXECUTABLE = grbl_sim_executable()
pytestmark = pytest.mark.skipif(
    EXECUTABLE is None, reason=f"{GRBL_SIM_ENV} does not name a grbl-sim executable"
)

RATE_DEG_MIN, ACCEL_DEG_S2 = 3600.0, 120.0
"""60 deg/s, 120 deg/s^2: a 45 degree move takes 1.25 s."""

TIMEOUTS = TableTimeouts(
    banner_s=5.0, reply_s=2.0, status_s=0.5, move_margin_s=2.0, hold_s=5.0, poll_s=0.1
)


@pytest.fixture
def firmware(tmp_path: Path) -> Iterator[FirmwarePty]:
    assert EXECUTABLE is not None
    pty = FirmwarePty(EXECUTABLE, tmp_path)
    try:
        _write_settings(pty.device_path, {110: RATE_DEG_MIN, 120: ACCEL_DEG_S2})
        yield pty
    finally:
        pty.close()


@pytest.fixture
def table(firmware: FirmwarePty) -> Iterator[GrblTable]:
    port = serial.serial_for_url(firmware.device_path, baudrate=115200, timeout=0.05)
    driver = GrblTable(port, timeouts=TIMEOUTS)
    driver.connect()  # the banner is long gone: this goes through Ctrl-X
    yield driver
    driver.close()


def _write_settings(device_path: str, settings: dict[int, float]) -> None:
    """Write ``$N=value`` lines, each answered ``ok``. A line sent while the firmware is
    still booting is lost to its reset (the banner comes instead of ``ok``): sent again."""
    with serial.serial_for_url(device_path, baudrate=115200, timeout=0.1) as port:
        for number, value in settings.items():
            for _attempt in range(5):
                port.write(f"${number}={value:.3f}\n".encode())
                answer = _read_until_match(port, re.compile(rb"(ok|help\]|error:\d+)\r\n$"), 5.0)
                if answer.endswith(b"ok\r\n"):
                    break
            else:
                raise AssertionError(f"${number}={value} not accepted: {answer!r}")


def test_turns_through_the_eight_views_and_the_barrier_waits_for_the_motion(table: GrblTable):
    assert table.settings[110] == RATE_DEG_MIN
    assert table.position_known
    for target in [45.0 * k for k in range(1, 8)] + [0.0, 12.345]:
        started = time.monotonic()
        before = table.position_deg()
        reached = table.goto_deg(target)
        took = time.monotonic() - started
        assert reached == pytest.approx(target, abs=0.2)
        # G4 P0 answers only once the firmware has stopped: no faster than the trapezoid
        distance = abs(target - before)
        rate = RATE_DEG_MIN / 60.0
        fastest = min(2 * (distance / ACCEL_DEG_S2) ** 0.5, distance / rate + rate / ACCEL_DEG_S2)
        assert took >= 0.9 * fastest
        status = table.status()
        assert (status.state, status.position_deg) == ("Idle", reached)


def test_a_feed_hold_interrupts_the_move_and_the_table_stops(table: GrblTable):
    thread, outcome = goto_in_background(table, 270.0)
    time.sleep(1.0)
    held = table.hold()
    thread.join(10)
    assert isinstance(outcome[0], TableHeld)
    assert (held.state, held.substate) == ("Hold", 0)
    time.sleep(0.5)
    assert table.position_deg() == held.position_deg
    with pytest.raises(TableHeld):
        table.goto_deg(0.0)
    table.resume()
    time.sleep(0.3)
    assert table.status().state in ("Run", "Idle")


def test_a_reset_mid_move_is_alarm_3_and_the_position_unknown(table: GrblTable):
    alarms: list[int] = []
    table.alarm_raised.connect(lambda code, meaning: alarms.append(code))
    thread, outcome = goto_in_background(table, 300.0)
    time.sleep(1.0)
    after = table.reset()
    thread.join(10)
    assert alarms == [3]
    assert isinstance(outcome[0], TableReset)  # the waiting G4 P0 died with it
    assert after.state == "Alarm"
    assert not table.position_known
    with pytest.raises(TableAlarm, match="ALARM:3"):
        table.goto_deg(0.0)
    assert table.unlock().state == "Idle"
    assert not table.position_known  # unlocking does not make the angle trustworthy
    table.confirm_position_known()
    assert table.goto_deg(0.0) == pytest.approx(0.0, abs=0.2)


def test_the_firmware_s_errors_are_typed(table: GrblTable):
    with pytest.raises(TableError) as caught:
        table.home()  # grbl-sim has no homing switch: $22=0
    assert caught.value.code == 5
    assert table.goto_deg(10.0) == pytest.approx(10.0, abs=0.2)


def test_a_homing_cycle_that_finds_no_switch_is_its_alarm_not_a_silent_controller(
    firmware: FirmwarePty,
):
    """Homing on (``$22=1``), a 3 s search (1.5 x 20 degrees of max travel at ``$25`` 10
    deg/s, Z first as the firmware's default cycles go) on a board with no switch wired
    (grbl-sim's pins read as a bare board's pull-ups, docs/TABLE.md): Grbl answers no ``?``
    while it searches, then reports ALARM:9. The driver had taken the silence for a dead
    controller after 2 s (``TableTimeout``)."""
    travels = {130: 20.0, 131: 20.0, 132: 20.0}
    _write_settings(firmware.device_path, {22: 1, **travels, 25: 600.0, 24: 300.0})
    port = serial.serial_for_url(firmware.device_path, baudrate=115200, timeout=0.05)
    table = GrblTable(port, timeouts=TIMEOUTS)
    try:
        table.connect()  # Idle: set while running, homing locks only from the next power-up
        with pytest.raises(TableAlarm) as caught:
            table.home()
        assert caught.value.code == 9
        assert not table.position_known
    finally:
        table.close()


def test_a_silent_controller_times_out_within_the_bound(table: GrblTable, firmware: FirmwarePty):
    bound = TIMEOUTS.move_margin_s + 1.5 * (90.0 / 60.0 + 60.0 / ACCEL_DEG_S2)
    thread, outcome = goto_in_background(table, 90.0)
    time.sleep(0.5)
    started = time.monotonic()
    firmware.freeze()
    thread.join(bound + 5.0)
    waited = time.monotonic() - started
    assert isinstance(outcome[0], TableTimeout)
    assert waited <= bound + 10.0  # generous: the firmware's own timing is checked above
    firmware.thaw()


def test_unplugging_mid_move_is_disconnected_and_the_position_unknown(
    table: GrblTable, firmware: FirmwarePty
):
    lost: list[str] = []
    table.disconnected.connect(lost.append)
    thread, outcome = goto_in_background(table, 200.0)
    time.sleep(1.0)
    firmware.unplug()
    thread.join(10)
    assert isinstance(outcome[0], TableDisconnected)
    assert lost
    assert not table.position_known


SCRIPT = (
    b"\x18", b"$$\n", b"?", b"?", b"?", b"$I\n", b"$G\n", b"\n", b"g0 x1.5\n", b"G4 P0 (sync)\n",
    b"?", b"G0 X10 Q3\n", b"G1 X2\n", b"$Z\n", b"$999=1\n", b"$H\n", b"$X\n", b"G0 X\n",
    b"$10=0\n", b"?", b"$10=1\n", b"\x18", b"?",
    b"$C x\n", b"$C\n", b"?", b"G0 X20\n", b"G4 P0\n", b"?", b"!", b"?", b"$H\n", b"$SLP\n",
    b"$X\n", b"$C\n", b"?", b"$SLP\n", b"?", b"!", b"?", b"\x18", b"?", b"$C\n", b"$X\n", b"?",
)  # fmt: skip
"""Exchanges whose answers do not depend on timing, each read to its last line: among them
check mode (``$C``: moves answered, nothing turns; ``$C`` again resets) and sleep (``$SLP``:
a reset wakes it, locked)."""

NORMALISE = (
    (rb"\$(\d+)=\d+\.\d{3}", rb"$\1=<dec>"),
    (rb"\$(\d+)=\d+\r", rb"$\1=<int>\r"),
    (rb"VER:1\.1h\.\d{8}", rb"VER:1.1h.<build>"),
    (rb"-?\d+\.\d{3}", rb"<n>"),
    (rb"FS:\d+,\d+", rb"FS:<n>,<n>"),
    (rb"\|(WCO|Ov):[^|>]*", rb""),  # present on Grbl's refresh counters
)


def _last_line(sent: bytes) -> re.Pattern[bytes]:
    if sent == b"?":
        return re.compile(rb">\r\n$")
    if sent == b"\x18":
        return re.compile(rb"help\]\r\n$")
    if sent in (b"!", b"~"):
        return re.compile(rb"")  # real-time: no answer of their own
    return re.compile(rb"(ok|error:\d+)\r\n$")


def _answers(device_path: str) -> list[bytes]:
    answers = []
    with serial.serial_for_url(device_path, baudrate=115200, timeout=0.05) as port:
        for sent in SCRIPT:
            port.write(sent)
            data = _read_until_match(port, _last_line(sent), 5.0)
            data += _read_for(port, 0.2)  # nothing more may follow
            for pattern, replacement in NORMALISE:
                data = re.sub(pattern, replacement, data)
            answers.append(data)
    return answers


def _read_until_match(port: serial.Serial, last: re.Pattern[bytes], timeout_s: float) -> bytes:
    data, deadline = b"", time.monotonic() + timeout_s
    while not last.search(data) and time.monotonic() < deadline:
        data += port.read(512)
    return data


def _read_for(port: serial.Serial, seconds: float) -> bytes:
    data, deadline = b"", time.monotonic() + seconds
    while time.monotonic() < deadline:
        data += port.read(512)
    return data


def test_the_simulated_controller_answers_byte_for_byte_like_the_firmware(
    firmware: FirmwarePty,
):
    from devices.table import GrblSimulator, PtyGrblServer

    simulator = PtyGrblServer(GrblSimulator(), time_scale=1.0, reset_on_open=False)
    with simulator.start() as simulated:
        ours = _answers(simulated.device_path)
    theirs = _answers(firmware.device_path)
    differences = [
        f"after {sent!r}: simulator {mine!r}, firmware {real!r}"
        for sent, mine, real in zip(SCRIPT, ours, theirs, strict=True)
        if mine != real
    ]
    assert not differences, "\n".join(differences)
