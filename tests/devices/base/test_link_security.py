"""Issue 23, findings 1-4 and 8: the base link fails closed and obeys only its owner."""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from typing import Any

import pytest
import zmq

from devices.base import (
    BaseAuthRejected,
    BaseClient,
    BaseError,
    BaseOffline,
    BaseState,
    ClientTiming,
    Pose,
    SimulatedBase,
)
from devices.base.keys import AUTHORIZED_CLIENTS_DIR
from devices.base.protocol import Command
from devices.base.server import ServerTiming

from ..fake_clock import FakeClock, wait_real

MakeSim = Callable[..., SimulatedBase]
MakeClient = Callable[..., BaseClient]
RawDealer = Callable[[str], zmq.Socket[bytes]]
QUICK = ClientTiming(request_timeout_s=0.3, retries=1)


def _ask(sock: zmq.Socket[bytes], request: dict[str, Any]) -> dict[str, Any] | None:
    sock.send_multipart([b"", json.dumps(request).encode()])
    if not sock.poll(5000):
        return None
    reply: dict[str, Any] = json.loads(sock.recv_multipart()[-1])
    return reply


def _goto(request_id: str, session: str | None, x_m: float = 1.0) -> dict[str, Any]:
    request: dict[str, Any] = {"v": 1, "id": request_id, "cmd": "goto"}
    request["args"] = {"goal_id": request_id, "x": x_m, "y": 0.0, "yaw_deg": 0.0}
    if session is not None:
        request["session"] = session
    return request


# --- 1. fail closed -------------------------------------------------------------------------


def test_a_dead_authenticator_lets_nobody_in_and_serves_nothing(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient
) -> None:
    sim = make_sim(keys=key_folders.server_keys())
    friend = make_client(sim.command_endpoint, keys=key_folders.client_keys(), timing=QUICK)
    assert friend.hello().name == "fieldapp-sim-base"
    sim.server.kill_authenticator()
    stranger = make_client(sim.command_endpoint, keys=key_folders.stranger_keys(), timing=QUICK)
    with pytest.raises(BaseError):
        stranger.goto("evil", Pose(1.0, 1.0, 0.0))
    with pytest.raises((BaseOffline, BaseAuthRejected)):  # a connection made before: no reply,
        friend.goto("g", Pose(1.0, 1.0, 0.0))  # and its reconnection is refused
    newcomer = make_client(sim.command_endpoint, keys=key_folders.client_keys(), timing=QUICK)
    with pytest.raises(BaseError):
        newcomer.status()
    assert sim.executed[Command.GOTO] == 0
    assert sim.pose == Pose(0.0, 0.0, 0.0)


# --- 2. revoked keys ------------------------------------------------------------------------


def test_a_revoked_key_is_refused_on_new_and_old_connections(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient, caplog: pytest.LogCaptureFixture
) -> None:
    clock = FakeClock()
    timing = ServerTiming(keys_reload_s=1.0)
    sim = make_sim(keys=key_folders.server_keys(), clock=clock, timing=timing)
    old = make_client(sim.command_endpoint, keys=key_folders.client_keys(), timing=QUICK)
    assert old.status().state is BaseState.IDLE
    (key_folders.base / AUTHORIZED_CLIENTS_DIR / "ws.key").unlink()
    clock.advance(1.0)  # the folder is checked every second of the base's clock
    assert wait_real(lambda: "revoked" in caplog.text)
    with pytest.raises(BaseAuthRejected):  # the old connection was cut: its handshake again
        old.goto("g", Pose(1.0, 0.0, 0.0))  # is refused, not "offline"
    with pytest.raises(BaseAuthRejected):
        make_client(sim.command_endpoint, keys=key_folders.client_keys(), timing=QUICK).hello()
    assert sim.executed[Command.GOTO] == 0


def test_a_revoked_key_s_telemetry_ends_and_the_other_clients_go_on(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient
) -> None:
    """ZeroMQ cannot drop one peer: the base binds its sockets again when a key is removed.
    The removed key's telemetry stops; a client still authorised reconnects by itself and is
    answered, its telemetry flows again."""
    friend_key = key_folders.stranger / "client.key"
    (key_folders.base / AUTHORIZED_CLIENTS_DIR / "friend.key").write_text(friend_key.read_text())
    clock = FakeClock()
    timing = ServerTiming(keys_reload_s=1.0)
    sim = make_sim(keys=key_folders.server_keys(), clock=clock, timing=timing)
    revoked = make_client(sim.command_endpoint, sim.telemetry_endpoint,
                          keys=key_folders.client_keys(), timing=QUICK)  # fmt: skip
    friend = make_client(sim.command_endpoint, sim.telemetry_endpoint,
                         keys=key_folders.stranger_keys())  # fmt: skip
    heard: dict[str, list[float]] = {"revoked": [], "friend": []}
    revoked.pose_received.connect(lambda t, _pose: heard["revoked"].append(t))
    friend.pose_received.connect(lambda t, _pose: heard["friend"].append(t))

    def hear_after(t_s: float, who: tuple[str, ...]) -> bool:
        clock.advance(0.5)  # a pose every second at rest, on the base's clock
        return all(any(t > t_s for t in heard[name]) for name in who)

    assert wait_real(lambda: hear_after(0.0, ("revoked", "friend")))
    (key_folders.base / AUTHORIZED_CLIENTS_DIR / "ws.key").unlink()
    clock.advance(1.0)  # the folder is read again: both sockets are bound again
    assert wait_real(lambda: _answers(friend))
    cut_s = clock()  # every pose from now on is stamped later
    assert wait_real(lambda: hear_after(cut_s + 3.0, ("friend",)))
    assert not any(t > cut_s for t in heard["revoked"])


def test_reload_keys_takes_a_new_key_at_once(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient
) -> None:
    clock = FakeClock()  # never advanced: only reload_keys() (SIGHUP) reads the folder
    sim = make_sim(keys=key_folders.server_keys(), clock=clock)
    stranger_key = key_folders.stranger / "client.key"
    with pytest.raises(BaseAuthRejected):
        make_client(sim.command_endpoint, keys=key_folders.stranger_keys(), timing=QUICK).hello()
    (key_folders.base / AUTHORIZED_CLIENTS_DIR / "new.key").write_text(stranger_key.read_text())
    sim.server.reload_keys()
    client = make_client(sim.command_endpoint, keys=key_folders.stranger_keys())
    assert wait_real(lambda: _answers(client))


def _answers(client: BaseClient) -> bool:
    try:
        client.status()
    except BaseError:
        return False
    return True


# --- 3. duplicates and replays --------------------------------------------------------------


def test_a_stop_reusing_a_goto_id_is_executed(
    tcp_sim: SimulatedBase, raw_dealer: RawDealer
) -> None:
    sim = tcp_sim
    sock = raw_dealer(sim.command_endpoint)
    session = sim.server.session
    assert _ask(sock, _goto("x-1", session, 4.0)) == {
        "v": 1, "id": "x-1", "ok": True, "result": {"accepted": True},
    }  # fmt: skip
    reply = _ask(sock, {"v": 1, "id": "x-1", "cmd": "stop", "session": session})
    assert reply == {"v": 1, "id": "x-1", "ok": True, "result": {}}
    assert sim.latched and sim.status().state is BaseState.STOPPED


def test_the_id_of_a_refused_request_is_used_too(
    tcp_sim: SimulatedBase, raw_dealer: RawDealer
) -> None:
    """The base keeps its replies to requests it could not run as well (the spec's "last 256
    replies"): the same bytes again get the same error, another request with that id is
    ``id reused`` and not run."""
    sock = raw_dealer(tcp_sim.command_endpoint)
    wrong_version = {"v": 2, "id": "r-1", "cmd": "reset"}
    first = _ask(sock, wrong_version)
    assert first is not None and first["error"]["code"] == "version"
    assert _ask(sock, wrong_version) == first
    reused = _ask(sock, {"v": 1, "id": "r-1", "cmd": "reset"})
    assert reused is not None and reused["error"] == {"code": "bad_request", "message": "id reused"}
    assert tcp_sim.executed[Command.RESET] == 0


def test_a_stop_carrying_another_session_s_value_is_executed(
    tcp_sim: SimulatedBase, raw_dealer: RawDealer
) -> None:
    """Refusing a stale session guards against replayed gotos; a stop does no harm replayed,
    and refusing one (a client that missed the base's restart) would leave the base moving."""
    sim = tcp_sim
    sock = raw_dealer(sim.command_endpoint)
    accepted = _ask(sock, _goto("s-1", sim.server.session, 4.0))
    assert accepted is not None and accepted["ok"]
    reply = _ask(sock, {"v": 1, "id": "s-2", "cmd": "stop", "session": "an-older-base"})
    assert reply == {"v": 1, "id": "s-2", "ok": True, "result": {}}
    assert sim.latched and sim.status().state is BaseState.STOPPED
    refused = _ask(sock, {"v": 1, "id": "s-3", "cmd": "reset", "session": "an-older-base"})
    assert refused is not None and refused["error"]["code"] == "stale_session"


def test_a_hello_carrying_another_session_s_value_learns_the_new_one(
    tcp_sim: SimulatedBase, raw_dealer: RawDealer
) -> None:
    """A client that puts the session "in every later request" greets a restarted base with
    the old value: the greeting is how it learns the new one (it changes nothing, replayed)."""
    sock = raw_dealer(tcp_sim.command_endpoint)
    hello = {"v": 1, "id": "h-1", "cmd": "hello", "args": {"client": "another tool"},
             "session": "an-older-base"}  # fmt: skip
    reply = _ask(sock, hello)
    assert reply is not None and reply["ok"], reply
    assert reply["result"]["session"] == tcp_sim.server.session


def test_a_retry_on_a_new_connection_with_the_same_key_is_not_executed_again(
    key_folders: Any, make_sim: MakeSim
) -> None:
    """With keys the reply cache is keyed by the client's public key (the spec), so a retry
    after a lost reply that comes on a new connection, as a REQ client's must, gets the
    cached reply and starts nothing."""
    sim = make_sim(keys=key_folders.server_keys())
    keys = key_folders.client_keys()
    context: zmq.Context[zmq.Socket[bytes]] = zmq.Context()
    sockets: list[zmq.Socket[bytes]] = []

    def connection() -> zmq.Socket[bytes]:
        sock = context.socket(zmq.DEALER)
        sockets.append(sock)
        sock.setsockopt(zmq.LINGER, 0)
        sock.curve_secretkey = keys.pair.secret.reveal()
        sock.curve_publickey = keys.pair.public
        sock.curve_serverkey = keys.server_public
        sock.connect(sim.command_endpoint)
        return sock

    try:
        first = connection()
        goto = _goto("k-1", sim.server.session, 4.0)
        accepted = _ask(first, goto)
        assert accepted is not None and accepted["ok"]
        assert _ask(first, {"v": 1, "id": "k-2", "cmd": "cancel", "args": {"goal_id": "k-1"}})
        first.close()
        retry = _ask(connection(), goto)
        assert retry == accepted
        assert sim.executed[Command.GOTO] == 1
        assert sim.status().state is not BaseState.MOVING
    finally:
        for sock in sockets:
            sock.close(linger=0)
        context.term()


def test_a_reused_id_with_another_request_is_refused(
    tcp_sim: SimulatedBase, raw_dealer: RawDealer
) -> None:
    sim = tcp_sim
    sock = raw_dealer(sim.command_endpoint)
    assert _ask(sock, {"v": 1, "id": "y-1", "cmd": "heartbeat"}) is not None
    reply = _ask(sock, _goto("y-1", sim.server.session))
    assert reply is not None and reply["error"] == {"code": "bad_request", "message": "id reused"}
    assert sim.executed[Command.GOTO] == 0


def test_the_reply_cache_is_per_client(tcp_sim: SimulatedBase, raw_dealer: RawDealer) -> None:
    sim = tcp_sim
    first, second = raw_dealer(sim.command_endpoint), raw_dealer(sim.command_endpoint)
    accepted = _ask(first, _goto("z-1", sim.server.session))
    assert accepted is not None and accepted["ok"]
    reply = _ask(second, {"v": 1, "id": "z-1", "cmd": "status"})
    assert reply is not None and reply["result"]["state"] == "moving"  # its own reply
    assert sim.executed[Command.STATUS] == 1


def test_a_captured_goto_replayed_after_a_restart_is_refused(
    make_sim: MakeSim, raw_dealer: RawDealer
) -> None:
    before = make_sim(tcp=True)
    captured = _goto("r-1", before.server.session)
    before.close()
    after = make_sim(tcp=True)
    assert after.server.session != captured["session"]
    sock = raw_dealer(after.command_endpoint)
    reply = _ask(sock, captured)
    assert reply is not None and reply["error"]["code"] == "stale_session"
    reply = _ask(sock, _goto("r-2", None))
    assert reply is not None and reply["error"]["code"] == "bad_request"  # goto needs it
    assert after.executed[Command.GOTO] == 0


def test_the_client_sends_the_session_and_greets_a_restarted_base(
    make_sim: MakeSim, make_client: MakeClient
) -> None:
    sim = make_sim()
    client = make_client(sim.command_endpoint)
    info = client.hello()
    assert info.session == sim.server.session
    sim.controller.session = "restarted"  # as if the base restarted behind the same address
    with pytest.raises(BaseError, match="stale_session"):
        client.status()
    client.goto("g", Pose(0.3, 0.0, 0.0), timeout_s=30.0)  # greets first, then drives
    assert sim.executed[Command.GOTO] == 1


# --- 4. the goal's owner feeds the watchdog -------------------------------------------------


def test_another_client_polling_does_not_keep_a_goal_alive(
    make_sim: MakeSim, make_client: MakeClient
) -> None:
    clock = FakeClock()
    sim = make_sim(time_scale=0.1, clock=clock)
    owner = make_client(sim.command_endpoint)
    owner.goto("g", Pose(3.0, 0.0, 0.0), wait=False)
    owner.close()  # the commanding client dies
    watcher = make_client(sim.command_endpoint)
    for _ in range(4):
        clock.advance(0.3)
        assert watcher.status().state is BaseState.MOVING or sim.latched
    assert wait_real(lambda: sim.latched)  # 1.2 s without a word from the owner
    assert sim.status().error == "link lost"


def test_another_process_with_the_same_key_does_not_keep_a_dead_app_s_goal_alive(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient
) -> None:
    """With keys the reply cache is the key's (a retry on a new connection is answered from
    it), but the watchdog is the connection's: a ``fieldapp base status`` beside the app,
    with the workstation's key, must not keep a dead app's goal going."""
    clock = FakeClock()
    sim = make_sim(keys=key_folders.server_keys(), time_scale=0.1, clock=clock)
    owner = make_client(sim.command_endpoint, keys=key_folders.client_keys())
    owner.goto("g", Pose(3.0, 0.0, 0.0), wait=False)
    owner.close()  # the app dies
    watcher = make_client(sim.command_endpoint, keys=key_folders.client_keys())
    for _ in range(4):
        clock.advance(0.3)
        assert watcher.status().state is BaseState.MOVING or sim.latched
    assert wait_real(lambda: sim.latched)
    assert sim.status().error == "link lost"


def test_heartbeats_with_the_goal_s_key_on_a_new_connection_keep_it_alive(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient
) -> None:
    """The spec's identity is the CURVE key: a client that opens a new socket (a new routing
    id) for each retry, as the ZeroMQ guide's Lazy Pirate does, goes on feeding its goal's
    watchdog with heartbeats; the same key's ``status`` polls do not (the test above)."""
    clock = FakeClock()
    sim = make_sim(keys=key_folders.server_keys(), time_scale=0.1, clock=clock)
    owner = make_client(sim.command_endpoint, keys=key_folders.client_keys())
    owner.goto("g", Pose(3.0, 0.0, 0.0), wait=False)
    owner.close()  # its socket is gone; the same workstation goes on from a new one
    reopened = make_client(sim.command_endpoint, keys=key_folders.client_keys())
    for _ in range(6):
        clock.advance(0.3)
        ticks = clock.reads
        assert wait_real(lambda ticks=ticks: clock.reads > ticks + 2)  # the base saw the time
        reopened.heartbeat()
    assert not sim.latched
    assert sim.status().state is BaseState.MOVING


def test_the_owner_s_heartbeats_keep_its_goal_alive_across_a_reconnection(
    make_sim: MakeSim, make_client: MakeClient, make_link: Callable[[str], Any]
) -> None:
    clock = FakeClock()
    sim = make_sim(tcp=True, time_scale=0.1, clock=clock)
    link = make_link(sim.command_endpoint)
    owner = make_client(link.endpoint)
    owner.goto("g", Pose(3.0, 0.0, 0.0), wait=False)
    link.drop_replies = 1  # a lost reply: the client reconnects (Lazy Pirate)
    for _ in range(4):
        beats = sim.executed[Command.HEARTBEAT]
        clock.advance(0.5)
        assert wait_real(lambda beats=beats: sim.executed[Command.HEARTBEAT] > beats)
    assert link.replies_dropped == 1
    assert sim.status().state is BaseState.MOVING


# --- 8. rejected handshakes are logged ------------------------------------------------------


def test_a_rejected_handshake_is_logged_with_the_key(
    key_folders: Any, make_sim: MakeSim, make_client: MakeClient, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    sim = make_sim(keys=key_folders.server_keys())
    stranger_keys = key_folders.stranger_keys()
    with pytest.raises(BaseAuthRejected):
        make_client(sim.command_endpoint, keys=stranger_keys, timing=QUICK).hello()
    assert wait_real(lambda: stranger_keys.pair.public.decode() in caplog.text)
    assert "rejected handshake" in caplog.text
