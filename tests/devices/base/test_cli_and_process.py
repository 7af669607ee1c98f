"""``fieldapp sim-base`` as a real process (killed mid-move), ``fieldapp base`` and ``keys``."""

from __future__ import annotations

import os
import re
import selectors
import signal
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from devices.base import BaseClient, BaseOffline, BaseState, Pose, SimulatedBase
from fieldapp.cli import main

MakeClient = Callable[..., BaseClient]


def _first_line(process: subprocess.Popen[str], timeout_s: float) -> str:
    assert process.stdout is not None
    selector = selectors.DefaultSelector()
    selector.register(process.stdout, selectors.EVENT_READ)
    if not selector.select(timeout_s):
        pytest.fail(f"sim-base printed nothing within {timeout_s} s")
    return process.stdout.readline()


@pytest.fixture
def sim_process() -> Iterator[tuple[subprocess.Popen[str], str]]:
    """``fieldapp sim-base`` on free ports in real time; yields (process, command endpoint)."""
    command = [sys.executable, "-m", "fieldapp", "sim-base", "--bind", "tcp://127.0.0.1:*"]
    command += ["--telemetry", "tcp://127.0.0.1:*", "--time-scale", "1"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = _first_line(process, 30.0)
        match = re.search(r"command (tcp://\S+) telemetry", line)
        assert match, line
        yield process, match.group(1)
    finally:
        if process.poll() is None:
            process.kill()
        process.communicate(timeout=60)


def test_killed_base_process_is_reported_offline(
    sim_process: tuple[subprocess.Popen[str], str], make_client: MakeClient
) -> None:
    process, endpoint = sim_process
    client = make_client(endpoint)
    client.goto("far", Pose(3.0, 0.0, 0.0), wait=False)
    outcome: list[BaseException] = []

    def follow() -> None:
        try:
            for _ in client.follow_goal("far", timeout_s=60.0):
                pass
        except BaseException as error:
            outcome.append(error)

    thread = threading.Thread(target=follow)
    thread.start()
    time.sleep(0.5)
    assert client.status().state is BaseState.MOVING
    os.kill(process.pid, signal.SIGKILL)
    thread.join(timeout=30.0)  # the retry budget is 3 x 0.5 s; benchmarks/ measures it
    assert len(outcome) == 1
    assert isinstance(outcome[0], BaseOffline)


def test_sim_base_survives_sighup(tmp_path: Path, make_client: MakeClient) -> None:
    """The spec has SIGHUP read the authorised-keys folder again (``ProtocolServer.reload_keys``,
    tested in test_link_security.py); the signal's default action had ended the base."""
    from devices.base.keys import AUTHORIZED_CLIENTS_DIR, ClientKeys, generate_key_pair

    base, workstation = tmp_path / "base", tmp_path / "ws"
    generate_key_pair(base, "base")
    generate_key_pair(workstation, "client")
    (base / AUTHORIZED_CLIENTS_DIR).mkdir()
    (base / AUTHORIZED_CLIENTS_DIR / "ws.key").write_text((workstation / "client.key").read_text())
    (workstation / "base.key").write_text((base / "base.key").read_text())
    command = [sys.executable, "-m", "fieldapp", "sim-base", "--bind", "tcp://127.0.0.1:*"]
    command += ["--telemetry", "tcp://127.0.0.1:*", "--keys", str(base)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        match = re.search(r"command (tcp://\S+) telemetry", _first_line(process, 30.0))
        assert match
        process.send_signal(signal.SIGHUP)
        client = make_client(match.group(1), keys=ClientKeys.from_dir(workstation))
        assert client.hello().name == "fieldapp-sim-base"
        assert process.poll() is None
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=60) == 0
    finally:
        if process.poll() is None:
            process.kill()
        process.communicate(timeout=60)


def test_sim_base_stops_cleanly_on_sigterm(sim_process: tuple[subprocess.Popen[str], str]) -> None:
    process, _endpoint = sim_process
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=60) == 0  # generous: a loaded machine


def test_base_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedBase("tcp://127.0.0.1:*", "tcp://127.0.0.1:*", time_scale=20.0) as sim:
        endpoint = sim.command_endpoint
        assert main(["base", "--endpoint", endpoint, "hello"]) == 0
        assert "protocol 1, frame map" in capsys.readouterr().out
        assert (
            main(["base", "--endpoint", endpoint, "goto", "1", "-0.5", "90", "--goal-id", "c1"])
            == 0
        )
        assert "arrived: goal c1" in capsys.readouterr().out
        assert abs(sim.pose.x_m - 1.0) <= 0.04 and abs(sim.pose.y_m + 0.5) <= 0.04
        assert main(["base", "--endpoint", endpoint, "stop"]) == 0
        assert main(["base", "--endpoint", endpoint, "goto", "0", "0", "0"]) == 1
        assert "base is stopped" in capsys.readouterr().err
        assert main(["base", "--endpoint", endpoint, "reset"]) == 0
        assert main(["base", "--endpoint", endpoint, "status"]) == 0
        assert capsys.readouterr().out.splitlines()[-1].startswith("idle: goal c1")
        assert main(["base", "--endpoint", endpoint, "goto", "9", "0", "0"]) == 1
        assert "outside the map" in capsys.readouterr().err


def test_base_command_line_reports_offline_and_insecure(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["base", "--endpoint", "tcp://127.0.0.1:9", "status"]) == 1
    assert "offline" in capsys.readouterr().err
    assert main(["base", "--endpoint", "tcp://10.1.2.3:5555", "status"]) == 1
    assert "without CURVE keys" in capsys.readouterr().err


def test_keys_generate_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["keys", "generate", str(tmp_path / "k"), "--name", "base"]) == 0
    assert stat.S_IMODE((tmp_path / "k" / "base.key_secret").stat().st_mode) == 0o600
    assert (tmp_path / "k" / "base.key").is_file()
    assert "base.key" in capsys.readouterr().out
    assert main(["keys", "generate", str(tmp_path / "k"), "--name", "base"]) == 1
    assert "already exists" in capsys.readouterr().err
    assert (
        main(["base", "--endpoint", "tcp://127.0.0.1:9", "--keys", str(tmp_path / "k"), "hello"])
        == 1
    )
    assert "client.key_secret" in capsys.readouterr().err
