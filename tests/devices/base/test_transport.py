"""The client is handed its transport: byte-level checks against a scripted one, and the factory."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from typing import Any

import pytest

from devices.base import (
    BaseClient,
    BaseError,
    BaseOffline,
    BaseState,
    BaseTransport,
    ClientTiming,
    Pose,
    SimFault,
    SimulatedBase,
    Status,
    open_base,
    open_transport,
)
from devices.base.channel import RetryPolicy
from devices.base.protocol import Reply
from devices.base.telemetry import PoseCallback, StateCallback

from ..fake_clock import FakeClock, wait_real

MakeSim = Callable[..., SimulatedBase]
MakeClient = Callable[..., BaseClient]

HELLO = {
    "name": "scripted",
    "protocol": 1,
    "session": "s-1",
    "frame": "map",
    "bounds": [0, 0, 1, 1],
}
IDLE = {"state": "idle", "goal_id": None, "pose": {"x": 0.0, "y": 0.0, "yaw_deg": 0.0},
        "battery_pct": 90.0, "error": None}  # fmt: skip


class ScriptedTransport:
    """A pure-Python :class:`BaseTransport`: records each request's bytes and policy and
    answers from ``results`` by command."""

    def __init__(self, results: dict[str, dict[str, Any]], telemetry: bool = False) -> None:
        self.results = results
        self.sent: list[tuple[str, dict[str, Any], RetryPolicy]] = []
        self.callbacks: tuple[PoseCallback, StateCallback] | None = None
        self.telemetry = telemetry
        self.closed = False

    @property
    def endpoint(self) -> str:
        return "scripted://base"

    @property
    def carries_telemetry(self) -> bool:
        return self.telemetry

    def request(self, request_id: str, data: bytes, policy: RetryPolicy) -> Reply:
        request = json.loads(data)
        self.sent.append((request_id, request, policy))
        return Reply.success(request_id, self.results[request["cmd"]])

    def subscribe(self, on_pose: PoseCallback, on_state: StateCallback) -> None:
        self.callbacks = (on_pose, on_state)

    def close(self) -> None:
        self.closed = True


def test_the_client_speaks_the_protocol_through_the_transport_it_is_handed() -> None:
    transport = ScriptedTransport({"hello": HELLO, "status": IDLE, "stop": {}})
    checked: BaseTransport = transport  # the scripted one is a BaseTransport
    timing = ClientTiming(request_timeout_s=0.7, retries=4)
    with BaseClient(checked, timing=timing) as client:
        assert client.endpoint == "scripted://base"
        assert client.hello().session == "s-1"
        assert client.status().state is BaseState.IDLE
        client.stop()
    assert transport.closed  # the client closes what it was handed
    assert transport.callbacks is None  # no telemetry asked of a transport without any
    hello, status, stop = (request for _id, request, _policy in transport.sent)
    assert hello == {"v": 1, "id": transport.sent[0][0], "cmd": "hello",
                     "args": {"client": "fieldapp 0.1"}}  # fmt: skip
    assert "session" not in hello
    assert status["session"] == stop["session"] == "s-1"  # every request after hello
    ids = [request_id for request_id, request, _policy in transport.sent]
    assert ids == [request["id"] for request in (hello, status, stop)]
    assert len(set(ids)) == 3 and len({i.rsplit("-", 1)[0] for i in ids}) == 1  # one session
    assert {policy for *_, policy in transport.sent} == {RetryPolicy(0.7, 4)}


def test_telemetry_from_the_transport_is_re_emitted_as_signals() -> None:
    transport = ScriptedTransport({}, telemetry=True)
    client = BaseClient(transport)
    poses: list[tuple[float, Pose]] = []
    states: list[Status] = []
    client.pose_received.connect(lambda t_s, pose: poses.append((t_s, pose)))
    client.state_received.connect(states.append)
    assert transport.callbacks is not None
    on_pose, on_state = transport.callbacks
    on_pose(12.5, Pose(1.0, 2.0, 3.0))
    on_state(Status.from_json(IDLE))
    client.close()
    assert poses == [(12.5, Pose(1.0, 2.0, 3.0))]
    assert [status.state for status in states] == [BaseState.IDLE]


def test_an_inproc_endpoint_needs_the_context_of_its_base() -> None:
    with pytest.raises(BaseError, match=r"inproc://nowhere.*context"):
        open_base("inproc://nowhere")
    with pytest.raises(BaseError, match=r"inproc://nowhere-telemetry.*context"):
        open_transport("tcp://127.0.0.1:5555", "inproc://nowhere-telemetry")


def test_a_transport_without_telemetry_refuses_to_subscribe() -> None:
    transport = open_transport("tcp://127.0.0.1:5555")
    try:
        assert not transport.carries_telemetry
        with pytest.raises(BaseError, match="no telemetry endpoint"):
            transport.subscribe(lambda _t, _pose: None, lambda _status: None)
    finally:
        transport.close()


def test_an_in_process_base_is_reached_without_a_port_and_its_end_is_offline(
    sim: SimulatedBase, make_client: MakeClient
) -> None:
    assert sim.command_endpoint.startswith("inproc://")
    client = make_client(sim.command_endpoint, timing=ClientTiming(0.25, retries=1))
    assert client.hello().session == sim.server.session
    sim.close()  # its socket is gone, and over inproc:// with it the client's only pipe:
    with pytest.raises(BaseOffline):  # a send must not block for want of a peer
        client.status()


def test_each_try_waits_on_the_client_s_clock(make_sim: MakeSim, make_client: MakeClient) -> None:
    """A frozen base: two tries of 30 s of the client's clock, gone in a moment of real time."""
    sim = make_sim()
    clock = FakeClock()
    client = make_client(sim.command_endpoint, clock=clock, timing=ClientTiming(30.0, retries=1))
    client.hello()
    sim.inject_fault(SimFault.FREEZE)
    failed: list[BaseException] = []

    def ask() -> None:
        try:
            while True:  # the request the loop was serving when it froze is still answered
                client.status()
        except BaseException as error:
            failed.append(error)

    thread = threading.Thread(target=ask)
    thread.start()
    start_s = clock()
    assert wait_real(lambda: _advance_unless(clock, bool(failed)))
    thread.join(timeout=20.0)
    assert isinstance(failed[0], BaseOffline)
    assert "no reply in 2 tries over 60.0 s" in str(failed[0])
    assert clock() - start_s >= 60.0


def _advance_unless(clock: FakeClock, done: bool) -> bool:
    """``done``, after moving ``clock`` on by half a second when it is not."""
    if not done:
        clock.advance(0.5)
    return done


class StaleHeartbeatTransport(ScriptedTransport):
    """The first heartbeat waits until ``release`` and then fails (the link of the goal before
    was lost); every later one is answered."""

    def __init__(self) -> None:
        super().__init__(
            {"hello": HELLO, "status": IDLE | {"state": "moving"}, "goto": {}, "heartbeat": {}}
        )
        self.first_heartbeat = threading.Event()
        self.release = threading.Event()
        self.heartbeats = 0

    def request(self, request_id: str, data: bytes, policy: RetryPolicy) -> Reply:
        if json.loads(data)["cmd"] == "heartbeat":
            self.heartbeats += 1
            if self.heartbeats == 1:
                self.first_heartbeat.set()
                assert self.release.wait(20)
                raise BaseOffline("no reply in 3 tries (the goal before)")
        return super().request(request_id, data, policy)


def test_a_heartbeat_failure_of_the_goal_before_does_not_end_the_next_goal() -> None:
    """Seen on a loaded machine: a beat waiting its turn behind a failed request of station 4
    reported that failure after station 5's goal had begun, and station 5 was skipped too."""
    transport = StaleHeartbeatTransport()
    with BaseClient(transport, timing=ClientTiming(heartbeat_period_s=0.01)) as client:
        client.goto("s04", Pose(0.5, 0.5, 0.0), wait=False)
        assert transport.first_heartbeat.wait(20)  # the beat of s04 is in flight
        client.goto("s05", Pose(0.6, 0.5, 0.0), wait=False)
        transport.release.set()  # ... and fails now, with s05 under way
        assert wait_real(lambda: transport.heartbeats >= 2 or client.link_error is not None)
        assert client.link_error is None
        assert next(client.follow_goal("s05")).state is BaseState.MOVING  # s05 goes on
