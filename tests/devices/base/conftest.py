"""Mobile base fixtures: simulated bases in process or on free loopback ports, key folders, a
lossy link.

``make_sim()`` serves in process (``inproc://`` on a ZeroMQ context shared with the clients the
test makes): the real client, sockets and server loop, no ports. ``make_sim(tcp=True)``, and any
base given CURVE keys, serves on loopback TCP: for what the network does (CURVE, ZAP,
reconnections, message size limits, raw bytes). ``make_client`` reaches either, by endpoint.
"""

from __future__ import annotations

import shutil
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zmq

from devices.base import (
    BaseClient,
    ClientKeys,
    ServerKeys,
    SimulatedBase,
    generate_key_pair,
    open_base,
)
from devices.base.keys import AUTHORIZED_CLIENTS_DIR
from devices.base.transport import new_inproc_endpoints

ANY_PORT = "tcp://127.0.0.1:*"


def _wait_for(predicate: Callable[[], bool], timeout_s: float, period_s: float = 0.01) -> float:
    """Seconds until ``predicate()`` held; fails the test after ``timeout_s``."""
    start_s = time.monotonic()
    while not predicate():
        if time.monotonic() - start_s > timeout_s:
            pytest.fail(f"condition not met within {timeout_s} s")
        time.sleep(period_s)
    return time.monotonic() - start_s


@pytest.fixture
def wait_for() -> Callable[[Callable[[], bool], float], float]:
    """``wait_for(predicate, timeout_s)``: seconds until it held; fails the test after that."""
    return _wait_for


@pytest.fixture
def inproc_context() -> Iterator[zmq.Context[zmq.Socket[bytes]]]:
    """The ZeroMQ context in-process bases bind on and their clients connect through; ended
    after them (they depend on it)."""
    context: zmq.Context[zmq.Socket[bytes]] = zmq.Context()
    yield context
    context.term()


@pytest.fixture
def make_sim(
    inproc_context: zmq.Context[zmq.Socket[bytes]],
) -> Iterator[Callable[..., SimulatedBase]]:
    """Start simulated bases (fast time by default), in process unless ``tcp=True`` or keys
    are given (CURVE is the network's); all closed at teardown."""
    started: list[SimulatedBase] = []

    def make(*, tcp: bool = False, **kwargs: object) -> SimulatedBase:
        kwargs.setdefault("time_scale", 20.0)
        if tcp or kwargs.get("keys") is not None:
            endpoints = (ANY_PORT, ANY_PORT)
        else:
            endpoints = new_inproc_endpoints("sim-base")
            kwargs["context"] = inproc_context
        base = SimulatedBase(*endpoints, **kwargs).start()  # type: ignore[arg-type]
        started.append(base)
        return base

    yield make
    for base in started:
        base.close()


@pytest.fixture
def sim(make_sim: Callable[..., SimulatedBase]) -> SimulatedBase:
    """An in-process simulated base."""
    return make_sim()


@pytest.fixture
def tcp_sim(make_sim: Callable[..., SimulatedBase]) -> SimulatedBase:
    """A simulated base on loopback TCP (raw sockets, message size limits)."""
    return make_sim(tcp=True)


@pytest.fixture
def make_client(
    inproc_context: zmq.Context[zmq.Socket[bytes]],
) -> Iterator[Callable[..., BaseClient]]:
    """``make_client(endpoint, telemetry=None, **open_base_kwargs)``, as the application makes
    one (``open_base``); an ``inproc://`` endpoint goes through the in-process bases' context."""
    clients: list[BaseClient] = []

    def make(endpoint: str, telemetry: str | None = None, **kwargs: object) -> BaseClient:
        if endpoint.startswith("inproc://"):
            kwargs["context"] = inproc_context
        client = open_base(endpoint, telemetry, **kwargs)  # type: ignore[arg-type]
        clients.append(client)
        return client

    yield make
    for client in clients:
        client.close()


@dataclass(frozen=True)
class KeyFolders:
    base: Path
    workstation: Path
    stranger: Path

    def server_keys(self) -> ServerKeys:
        return ServerKeys.from_dir(self.base)

    def client_keys(self) -> ClientKeys:
        return ClientKeys.from_dir(self.workstation)

    def stranger_keys(self) -> ClientKeys:
        return ClientKeys.from_dir(self.stranger)


@pytest.fixture
def key_folders(tmp_path: Path) -> KeyFolders:
    """A base, an authorised workstation, and a stranger who knows the base's public key."""
    folders = KeyFolders(tmp_path / "base", tmp_path / "ws", tmp_path / "stranger")
    generate_key_pair(folders.base, "base")
    generate_key_pair(folders.workstation, "client")
    generate_key_pair(folders.stranger, "client")
    (folders.base / AUTHORIZED_CLIENTS_DIR).mkdir()
    shutil.copy(
        folders.workstation / "client.key", folders.base / AUTHORIZED_CLIENTS_DIR / "ws.key"
    )
    for folder in (folders.workstation, folders.stranger):
        shutil.copy(folders.base / "base.key", folder / "base.key")
    return folders


class LossyLink:
    """A ZeroMQ relay between clients and a base's command socket that can lose messages.

    ``blackhole`` drops everything both ways (a dead Wi-Fi link); ``drop_replies`` drops that
    many replies (the request was executed, its reply lost).
    """

    def __init__(self, backend_endpoint: str) -> None:
        self._context: zmq.Context[zmq.Socket[bytes]] = zmq.Context()
        self._front = self._context.socket(zmq.ROUTER)
        self._front.setsockopt(zmq.ROUTER_HANDOVER, 1)  # as the base: clients keep their id
        self._front.bind(ANY_PORT)
        self._back = self._context.socket(zmq.DEALER)
        self._back.connect(backend_endpoint)
        for sock in (self._front, self._back):
            sock.setsockopt(zmq.LINGER, 0)
        self.endpoint = self._front.getsockopt_string(zmq.LAST_ENDPOINT)
        self.blackhole = False
        self.drop_replies = 0
        self.replies_dropped = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        poller = zmq.Poller()
        poller.register(self._front, zmq.POLLIN)
        poller.register(self._back, zmq.POLLIN)
        while not self._stop.is_set():
            events = dict(poller.poll(timeout=10))
            if self._front in events:
                frames = self._front.recv_multipart()
                if not self.blackhole:
                    self._back.send_multipart(frames)
            if self._back in events:
                frames = self._back.recv_multipart()
                if self.blackhole:
                    continue
                if self.drop_replies > 0:
                    self.drop_replies -= 1
                    self.replies_dropped += 1
                    continue
                self._front.send_multipart(frames)
        self._front.close()
        self._back.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._context.term()


@pytest.fixture
def make_link() -> Iterator[Callable[[str], LossyLink]]:
    links: list[LossyLink] = []

    def make(backend_endpoint: str) -> LossyLink:
        link = LossyLink(backend_endpoint)
        links.append(link)
        return link

    yield make
    for link in links:
        link.close()


@pytest.fixture
def raw_dealer() -> Iterator[Callable[[str], zmq.Socket[bytes]]]:
    """Plain (NULL security) DEALER sockets for speaking bytes to a base."""
    context: zmq.Context[zmq.Socket[bytes]] = zmq.Context()
    sockets: list[zmq.Socket[bytes]] = []

    def make(endpoint: str) -> zmq.Socket[bytes]:
        sock = context.socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(endpoint)
        sockets.append(sock)
        return sock

    yield make
    for sock in sockets:
        sock.close()
    context.term()
