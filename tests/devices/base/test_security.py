"""CURVE keys, authorisation and the loopback-only rule, over real sockets."""

from __future__ import annotations

import json
import logging
import socket
import stat
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import zmq

from devices.base import (
    BaseAuthRejected,
    BaseClient,
    BaseState,
    ClientKeys,
    InsecureEndpoint,
    KeyFileError,
    Pose,
    SimulatedBase,
    generate_key_pair,
    open_base,
)
from devices.base.keys import is_loopback, load_key_pair

from ..fake_clock import wait_real

MakeSim = Callable[..., SimulatedBase]
MakeClient = Callable[..., BaseClient]


def test_generated_secret_key_is_private_and_loads(tmp_path: Path) -> None:
    public_path, secret_path = generate_key_pair(tmp_path / "keys", "client")
    assert stat.S_IMODE(secret_path.stat().st_mode) == 0o600
    assert stat.S_IMODE(public_path.stat().st_mode) & 0o077 in (0o044, 0o004, 0o040, 0o000)
    pair = load_key_pair(secret_path)
    assert len(pair.public) == 40
    assert len(pair.secret.reveal()) == 40
    assert pair.public.decode() in public_path.read_text()
    assert pair.secret.reveal().decode() not in public_path.read_text()
    with pytest.raises(KeyFileError, match="already exists"):
        generate_key_pair(tmp_path / "keys", "client")
    with pytest.raises(KeyFileError, match="key name"):
        generate_key_pair(tmp_path / "keys", "../evil")


def test_secret_keys_never_show_in_reprs_or_logs(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    server_keys, client_keys = key_folders.server_keys(), key_folders.client_keys()
    secrets = [server_keys.pair.secret.reveal().decode(), client_keys.pair.secret.reveal().decode()]
    sim = make_sim(keys=server_keys)
    client = make_client(sim.command_endpoint, sim.telemetry_endpoint, keys=client_keys)
    client.goto("g", Pose(0.3, 0.0, 0.0), timeout_s=10.0)
    texts = [repr(server_keys), repr(client_keys), str(client_keys.pair.secret), caplog.text]
    for secret in secrets:
        assert all(secret not in text for text in texts)
    assert "SecretKey(<hidden>)" in repr(client_keys)


@pytest.mark.parametrize(
    ("endpoint", "loopback"),
    [
        ("tcp://127.0.0.1:5555", True),
        ("tcp://127.3.2.1:5555", True),
        ("tcp://localhost:5555", True),
        ("tcp://[::1]:5555", True),
        ("ipc:///tmp/base", True),
        ("tcp://*:5555", False),
        ("tcp://0.0.0.0:5555", False),
        ("tcp://192.168.1.20:5555", False),
        ("tcp://robot.local:5555", False),
        ("udp://127.0.0.1:5555", False),
    ],
)
def test_loopback_detection(endpoint: str, loopback: bool) -> None:
    assert is_loopback(endpoint) is loopback


def test_both_ends_refuse_non_loopback_without_keys(key_folders: Any) -> None:
    with pytest.raises(InsecureEndpoint, match=r"tcp://\*:5555.*without CURVE keys"):
        SimulatedBase("tcp://*:5555", "tcp://127.0.0.1:*")
    with pytest.raises(InsecureEndpoint, match=r"192\.168\.1\.20"):
        open_base("tcp://192.168.1.20:5555")
    with pytest.raises(InsecureEndpoint):
        open_base("tcp://127.0.0.1:5555", "tcp://192.168.1.20:5556")
    open_base("tcp://192.168.1.20:5555", keys=key_folders.client_keys()).close()  # allowed


def test_authorised_client_drives_the_base_and_gets_telemetry(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient
) -> None:
    sim = make_sim(keys=key_folders.server_keys())
    client = make_client(
        sim.command_endpoint, sim.telemetry_endpoint, keys=key_folders.client_keys()
    )
    states: list[BaseState] = []
    client.state_received.connect(lambda status: states.append(status.state))
    assert client.hello().name == "fieldapp-sim-base"
    assert client.goto("g", Pose(0.5, 0.5, 45.0), timeout_s=10.0).state is BaseState.ARRIVED
    assert wait_real(lambda: BaseState.ARRIVED in states)


def test_unknown_key_is_rejected_as_such_and_executes_nothing(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient
) -> None:
    sim = make_sim(keys=key_folders.server_keys())
    stranger = make_client(
        sim.command_endpoint, sim.telemetry_endpoint, keys=key_folders.stranger_keys()
    )
    poses: list[Pose] = []
    stranger.pose_received.connect(lambda _t, pose: poses.append(pose))
    with pytest.raises(BaseAuthRejected, match="authentication rejected") as caught:
        stranger.goto("evil", Pose(1.0, 1.0, 0.0))  # not BaseOffline after the retries
    assert "authorized_clients" in str(caught.value)
    time.sleep(1.2)  # over a telemetry period
    assert sum(sim.executed.values()) == 0
    assert sim.pose == Pose(0.0, 0.0, 0.0)
    assert poses == []


def test_client_with_a_wrong_base_key_reports_a_handshake_failure(
    key_folders: Any, tmp_path: Path, make_sim: MakeSim, make_client: MakeClient
) -> None:
    sim = make_sim(keys=key_folders.server_keys())
    generate_key_pair(tmp_path / "impostor", "base")
    pair = key_folders.client_keys().pair
    wrong = ClientKeys(
        pair, (tmp_path / "impostor" / "base.key").read_text().split('"')[1].encode()
    )
    with pytest.raises(BaseAuthRejected, match="handshake failed"):
        make_client(sim.command_endpoint, keys=wrong).hello()
    assert sum(sim.executed.values()) == 0


def test_null_security_and_raw_tcp_get_nothing(
    key_folders: Any,
    make_sim: MakeSim,
    make_client: MakeClient,
    raw_dealer: Callable[[str], zmq.Socket[bytes]],
) -> None:
    sim = make_sim(keys=key_folders.server_keys())
    request = json.dumps({"v": 1, "id": "x-1", "cmd": "stop"}).encode()
    plain = raw_dealer(sim.command_endpoint)
    plain.send_multipart([b"", request])
    assert plain.poll(1000) == 0
    port = int(sim.command_endpoint.rsplit(":", 1)[1])
    with socket.create_connection(("127.0.0.1", port), timeout=1.0) as raw:
        raw.sendall(b"\xff" + b"\x00" * 8 + b"\x7f" + request)
        raw.settimeout(1.0)
        try:
            received = raw.recv(4096)
        except (TimeoutError, ConnectionResetError):
            received = b""
        assert b"x-1" not in received and b"ok" not in received
    with pytest.raises(BaseAuthRejected):
        make_client(sim.command_endpoint).hello()  # our own client without keys
    assert sum(sim.executed.values()) == 0
    assert not sim.latched
    assert (
        make_client(sim.command_endpoint, keys=key_folders.client_keys()).status().state
        is BaseState.IDLE
    )
