"""``fieldapp table`` and ``fieldapp sim-table`` end to end: output, exit codes, one-line errors."""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Callable

import pytest

from devices.table import GrblSimulator, PtyGrblServer
from fieldapp.cli import main

MakeServer = Callable[..., PtyGrblServer]


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_goto_and_status_print_the_angle(
    server: PtyGrblServer, capsys: pytest.CaptureFixture[str]
) -> None:
    assert run_cli(capsys, "table", "--port", server.device_path, "goto", "45") == (
        0,
        "table at 45.000 deg\n",
        "",
    )
    code, out, _ = run_cli(capsys, "table", "--port", server.device_path, "status")
    assert (code, out) == (0, "Idle at 45.000 deg\n")
    assert server.simulator.angle_deg == pytest.approx(45.0)


def test_park_turns_back_to_machine_zero_and_confirm_trusts_the_position(
    server: PtyGrblServer, capsys: pytest.CaptureFixture[str]
) -> None:
    run_cli(capsys, "table", "--port", server.device_path, "goto", "90")
    assert run_cli(capsys, "table", "--port", server.device_path, "park") == (
        0,
        "parked: table at 0.000 deg\n",
        "",
    )
    assert server.simulator.angle_deg == pytest.approx(0.0, abs=0.2)
    code, out, _ = run_cli(capsys, "table", "--port", server.device_path, "confirm")
    assert (code, out) == (0, "confirmed: Idle at 0.000 deg\n")


@pytest.mark.parametrize(
    ("action", "expected"),
    [("hold", "held: Hold:0 at 0.000 deg"), ("reset", "reset: Idle at 0.000 deg")],
)
def test_hold_and_reset(
    server: PtyGrblServer, capsys: pytest.CaptureFixture[str], action: str, expected: str
) -> None:
    code, out, _ = run_cli(capsys, "table", "--port", server.device_path, action)
    assert code == 0
    assert out.startswith(expected)


def test_home_when_enabled(make_server: MakeServer, capsys: pytest.CaptureFixture[str]) -> None:
    server = make_server(GrblSimulator(settings={22: 1}))
    code, out, _ = run_cli(capsys, "table", "--port", server.device_path, "home")
    assert (code, out) == (0, "homed: table at 0.000 deg\n")


@pytest.mark.parametrize(
    ("setup", "argv", "message"),
    [
        (None, ["--port", "/dev/ttyNOPE0", "status"], "cannot open serial port '/dev/ttyNOPE0'"),
        ({22: 1}, ["goto", "10"], "table in alarm"),
        ({}, ["home"], "error:5"),
        ({}, ["goto", "nan"], "not a usable number"),
        ("silent", ["--timeout", "0.3", "status"], "no Grbl banner"),
    ],
)
def test_errors_are_one_clear_line(
    make_server: MakeServer,
    capsys: pytest.CaptureFixture[str],
    setup: object,
    argv: list[str],
    message: str,
) -> None:
    if setup is not None:
        settings = setup if isinstance(setup, dict) else None
        server = make_server(GrblSimulator(settings=settings))
        server.simulator.set_silent(setup == "silent")
        argv = ["--port", server.device_path, *argv]
    code, out, err = run_cli(capsys, "table", *argv)
    assert (code, out) == (1, "")
    assert err.startswith("fieldapp table: ")
    assert message in err
    assert err.count("\n") == 1
    assert "Traceback" not in err


def test_sim_table_serves_until_interrupted(capsys: pytest.CaptureFixture[str]) -> None:
    process = subprocess.Popen(
        [sys.executable, "-m", "fieldapp", "sim-table"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        path = process.stdout.readline().strip()
        assert path.startswith("/dev/")
        code, out, _ = run_cli(capsys, "table", "--port", path, "goto", "30")
        assert (code, out) == (0, "table at 30.000 deg\n")
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=60) == 0  # generous: a loaded machine
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        for stream in (process.stdout, process.stderr):
            if stream is not None:
                stream.close()
