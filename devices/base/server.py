"""The protocol server shared by the simulated base and the ROS bridge.

A ROUTER socket for commands and a PUB socket for telemetry (both CURVE with a ZAP handler when
keys are given, loopback only otherwise), ZMQ_MAXMSGSIZE 65536, and one loop thread that answers
requests, ticks the :class:`BaseController` (watchdog, stop latch) and publishes telemetry.

Security (``shared/spec/base-protocol.md``): the sockets enforce ZAP, so with no handler no
CURVE client gets in, and the loop serves nothing while the handler thread is dead (fail
closed); the authorised-keys folder is re-read every ``keys_reload_s`` (or at once after
:meth:`ProtocolServer.reload_keys`); when a key was removed both sockets are bound again, so
every client shakes hands again and the removed one is refused (its requests, its telemetry),
and a request from a removed key still in flight is dropped. Replies are
cached per client (its CURVE key with keys, its routing id without) and request id: a
byte-identical retry gets the cached reply, another request with a used id is refused (``id
reused``), a ``stop`` always runs.

With ``context`` the server binds on a ZeroMQ context it is handed and leaves open (an
in-process base on ``inproc://``, reached by clients sharing that context); otherwise it makes
its own and terminates it on :meth:`ProtocolServer.close`.

Faults for tests: :meth:`ProtocolServer.freeze` (alive but silent), :meth:`ProtocolServer.crash`
(sockets gone at once, nothing halted), :meth:`ProtocolServer.kill_authenticator`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import zmq
from zmq.auth.thread import ThreadAuthenticator

from devices.base.auth import ZAP_DOMAIN, AuthorizedKeys, enforce_zap
from devices.base.controller import BaseController, ClientId
from devices.base.keys import ServerKeys, require_loopback_without_keys
from devices.base.protocol import (
    MAX_MESSAGE_BYTES,
    BaseState,
    Command,
    ErrorCode,
    ProtocolError,
    Reply,
    Status,
    decode_request,
    encode_pose_telemetry,
    encode_reply,
    encode_state_telemetry,
)

log = logging.getLogger(__name__)

REBIND_TRIES = 50
REBIND_WAIT_S = 0.02
"""Binding a socket's endpoint again after a key was removed: tries, and the wait between
them while ZeroMQ's I/O thread releases the closed socket's listener."""


@dataclass(frozen=True)
class ServerTiming:
    reply_cache_size: int = 256
    poll_period_s: float = 0.01
    pose_period_moving_s: float = 0.05
    pose_period_rest_s: float = 1.0
    state_period_s: float = 1.0
    keys_reload_s: float = 1.0
    """How often the authorised-keys folder is checked for changes (the spec: within 2 s)."""


@dataclass(frozen=True)
class _Answered:
    request: bytes
    reply: bytes


class ReplyCache:
    """The last ``size`` replies of each client by request id, for at most ``clients`` clients
    (the least recently heard is forgotten first)."""

    def __init__(self, size: int, clients: int = 64) -> None:
        self._size = size
        self._clients = clients
        self._by_client: OrderedDict[ClientId, OrderedDict[str, _Answered]] = OrderedDict()

    def get(self, client: ClientId, request_id: str) -> _Answered | None:
        replies = self._by_client.get(client)
        return None if replies is None else replies.get(request_id)

    def put(self, client: ClientId, request_id: str, request: bytes, reply: bytes) -> None:
        replies = self._by_client.setdefault(client, OrderedDict())
        self._by_client.move_to_end(client)
        replies[request_id] = _Answered(request, reply)
        while len(replies) > self._size:
            replies.popitem(last=False)
        while len(self._by_client) > self._clients:
            self._by_client.popitem(last=False)

    def __len__(self) -> int:
        return sum(len(replies) for replies in self._by_client.values())


def split_envelope(frames: list[bytes]) -> tuple[list[bytes], list[bytes]]:
    """(routing envelope, body) of a ROUTER message from a REQ (empty delimiter) or a DEALER."""
    cut = frames.index(b"", 1) + 1 if b"" in frames[1:] else 1
    return frames[:cut], frames[cut:]


class ProtocolServer:
    """Serves fieldapp-base/1 for a :class:`BaseController` on one loop thread."""

    def __init__(
        self,
        controller: BaseController,
        command_endpoint: str,
        telemetry_endpoint: str,
        keys: ServerKeys | None = None,
        timing: ServerTiming | None = None,
        clock: Callable[[], float] = time.monotonic,
        context: zmq.Context[zmq.Socket[bytes]] | None = None,
    ) -> None:
        for endpoint in (command_endpoint, telemetry_endpoint):
            require_loopback_without_keys(endpoint, keys is not None)
        self.controller = controller
        self.timing = timing or ServerTiming()
        self._endpoints = (command_endpoint, telemetry_endpoint)
        self._keys = keys
        self._clock = clock
        self._cache = ReplyCache(self.timing.reply_cache_size)
        self._lock = threading.Lock()
        self._status = controller.status()
        self._stopping = threading.Event()
        self._frozen = threading.Event()
        self._crashed = threading.Event()
        self._thread: threading.Thread | None = None
        self._shared_context = context
        self._context: zmq.Context[zmq.Socket[bytes]] | None = None
        self._auth: ThreadAuthenticator | None = None
        self._authorized = AuthorizedKeys(keys.authorized_dir) if keys is not None else None
        self._reload_asked = threading.Event()
        self._auth_lost_logged = False
        self.command_endpoint = command_endpoint
        self.telemetry_endpoint = telemetry_endpoint
        self.on_tick: Callable[[Status], None] | None = None

    # --- lifecycle ---

    def start(self) -> None:
        """Bind both sockets and start serving; endpoints with port ``*`` are resolved."""
        self._context = zmq.Context() if self._shared_context is None else self._shared_context
        if self._keys is not None:
            self._auth = ThreadAuthenticator(
                self._context, log=logging.getLogger(f"{__name__}.zap")
            )
            self._auth.start()
            self._auth.configure_curve_callback(ZAP_DOMAIN, credentials_provider=self._authorized)
        router = self._socket(self._context, zmq.ROUTER)
        publisher = self._socket(self._context, zmq.PUB)
        try:
            router.bind(self._endpoints[0])
            publisher.bind(self._endpoints[1])
        except zmq.ZMQError:
            router.close(linger=0)
            publisher.close(linger=0)
            self._shutdown_context()
            raise
        self.command_endpoint = router.getsockopt_string(zmq.LAST_ENDPOINT)
        self.telemetry_endpoint = publisher.getsockopt_string(zmq.LAST_ENDPOINT)
        self._thread = threading.Thread(
            target=self._serve, args=(router, publisher), name="base-server", daemon=True
        )
        self._thread.start()
        log.info("serving %s (telemetry %s)", self.command_endpoint, self.telemetry_endpoint)

    def _socket(self, context: zmq.Context[zmq.Socket[bytes]], kind: int) -> zmq.Socket[bytes]:
        sock = context.socket(kind)
        sock.setsockopt(zmq.LINGER, 0)
        if kind == zmq.ROUTER:
            sock.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
            sock.setsockopt(zmq.ROUTER_HANDOVER, 1)  # a client's reconnection keeps its id
        if self._keys is not None:
            enforce_zap(sock)
            sock.curve_secretkey = self._keys.pair.secret.reveal()
            sock.curve_publickey = self._keys.pair.public
            sock.curve_server = True
        return sock

    def close(self) -> None:
        """Halt the base, stop serving and release the sockets."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._shutdown_context()

    def _shutdown_context(self) -> None:
        if self._auth is not None:
            self._auth.stop()
            self._auth = None
        if self._context is not None and self._context is not self._shared_context:
            self._context.term()
        self._context = None

    def freeze(self, frozen: bool = True) -> None:
        """Stop (or resume) answering, publishing and updating, like a hung computer."""
        if frozen:
            self._frozen.set()
        else:
            self._frozen.clear()

    def _faulted(self) -> bool:
        """Frozen or crashed: not one more reply or message."""
        return self._frozen.is_set() or self._crashed.is_set()

    def crash(self) -> None:
        """Drop both sockets at once without halting anything, like a dead process."""
        self._crashed.set()

    def kill_authenticator(self) -> None:
        """Fault for tests: the ZAP handler thread ends (the base must then serve nothing)."""
        if self._auth is not None:
            self._auth.stop()

    def reload_keys(self) -> None:
        """Read the authorised-keys folder again now (e.g. on SIGHUP); thread-safe."""
        self._reload_asked.set()

    @property
    def session(self) -> str:
        """The value ``hello`` returns; new at every start of the base."""
        return self.controller.session

    def status(self) -> Status:
        with self._lock:
            return self._status

    # --- loop ---

    def _serve(self, router: zmq.Socket[bytes], publisher: zmq.Socket[bytes]) -> None:
        telemetry = TelemetrySchedule()
        poller = zmq.Poller()
        poller.register(router, zmq.POLLIN)
        next_reload_s = self._clock() + self.timing.keys_reload_s
        revocations = 0 if self._authorized is None else self._authorized.revocations
        try:
            while not self._stopping.is_set() and not self._crashed.is_set():
                if self._frozen.is_set():
                    time.sleep(self.timing.poll_period_s)
                    continue
                events = dict(poller.poll(timeout=round(self.timing.poll_period_s * 1000)))
                if self._faulted():
                    continue  # a fault injected during the poll: not one more reply
                now_s = self._clock()
                if self._reload_asked.is_set() or now_s >= next_reload_s:
                    self._reload_asked.clear()
                    next_reload_s = now_s + self.timing.keys_reload_s
                    if self._authorized is not None:
                        self._authorized.refresh()
                        if self._authorized.revocations != revocations:
                            revocations = self._authorized.revocations
                            router, publisher = self._reconnect_everyone(router, publisher)
                            poller = zmq.Poller()
                            poller.register(router, zmq.POLLIN)
                serving = self._authenticator_alive()
                if router in events:
                    self._drain(router, serving)
                    if self._faulted():
                        continue  # ... or while answering: no telemetry either
                if serving:
                    self._tick(publisher, telemetry)
                else:
                    self.controller.tick(now_s)  # the watchdog still halts a goal
        finally:
            if not self._crashed.is_set():
                self.controller.backend.halt()
            router.close(linger=0)
            publisher.close(linger=0)

    def _reconnect_everyone(
        self, router: zmq.Socket[bytes], publisher: zmq.Socket[bytes]
    ) -> tuple[zmq.Socket[bytes], zmq.Socket[bytes]]:
        """A key was removed: both sockets are closed and bound again, so that every client
        connects and shakes hands again. The removed key's are refused (its client reports
        "authentication rejected", its telemetry ends, as the spec says of connections already
        made); the others' ZeroMQ sockets reconnect by themselves, and a request lost meanwhile
        is retried and answered from the reply cache. ZeroMQ cannot drop one peer alone."""
        log.warning("a client key was removed: every client must connect again")
        context = self._context
        assert context is not None  # the loop runs between start() and close()
        router.close(linger=0)
        publisher.close(linger=0)
        return (
            self._bound_again(self._socket(context, zmq.ROUTER), self.command_endpoint),
            self._bound_again(self._socket(context, zmq.PUB), self.telemetry_endpoint),
        )

    def _bound_again(self, sock: zmq.Socket[bytes], endpoint: str) -> zmq.Socket[bytes]:
        """``sock`` bound to ``endpoint``, which the socket just closed held: its listener is
        released by ZeroMQ's I/O thread, a moment later."""
        tries = 1
        while True:
            try:
                sock.bind(endpoint)
                return sock
            except zmq.ZMQError as error:
                if error.errno != zmq.EADDRINUSE or tries == REBIND_TRIES:
                    sock.close(linger=0)
                    raise
            tries += 1
            time.sleep(REBIND_WAIT_S)

    def _authenticator_alive(self) -> bool:
        """False when keys are in use but the ZAP handler is gone: then nothing is served."""
        if self._keys is None or (self._auth is not None and self._auth.is_alive()):
            return True
        if not self._auth_lost_logged:
            self._auth_lost_logged = True
            log.error("the authenticator (ZAP handler) is not running: serving nothing")
        return False

    def _drain(self, router: zmq.Socket[bytes], serving: bool) -> None:
        for _ in range(100):
            if self._faulted():
                return  # a fault injected between two requests: the later ones wait, unanswered
            try:
                frames = router.recv_multipart(zmq.NOBLOCK, copy=False)
            except zmq.Again:
                return
            if not serving:
                continue
            client = self._client_of(frames)
            if client is None:
                continue
            envelope, reply = self._answer([frame.bytes for frame in frames], client)
            router.send_multipart([*envelope, reply])

    def _client_of(self, frames: list[zmq.Frame]) -> ClientId | None:
        """Who sent ``frames`` (:data:`ClientId`); None (and logged) for a key no longer
        authorised."""
        routing_id = frames[0].bytes
        if self._authorized is None:
            return (b"", routing_id)
        try:
            user = str(frames[-1].get("User-Id")).encode("ascii")
        except (zmq.ZMQError, UnicodeEncodeError):
            user = b""
        if not self._authorized.allows(user):
            log.warning("request from client key %s refused: not authorised (revoked?)",
                        user.decode() or "<none>")  # fmt: skip
            return None
        return (user, routing_id)

    def _answer(self, frames: list[bytes], client: ClientId) -> tuple[list[bytes], bytes]:
        envelope, body = split_envelope(frames)
        if len(body) != 1:
            log.warning("a message of %d body frames: answered bad_request", len(body))
            reply = Reply.failure(None, ErrorCode.BAD_REQUEST, "a request is exactly one frame")
            return envelope, encode_reply(reply)
        # the spec keys the replies by the client's CURVE key where there is one: a retry after a
        # lost reply comes on a new connection (a REQ client must reconnect) and is not run again
        replier: ClientId = (client[0], b"") if client[0] else client
        try:
            request = decode_request(body[0])
        except ProtocolError as error:
            log.warning("bad request (id %r): %s", error.request_id, error.message)
            if error.request_id is None:
                return envelope, encode_reply(Reply.failure(None, error.code, error.message))
            repeated = self._repeated(replier, error.request_id, body[0])
            if repeated is not None:
                return envelope, repeated
            data = encode_reply(Reply.failure(error.request_id, error.code, error.message))
            self._cache.put(replier, error.request_id, body[0], data)  # its id is used
            return envelope, data
        if request.cmd is not Command.STOP:
            repeated = self._repeated(replier, request.id, body[0])
            if repeated is not None:
                return envelope, repeated
        data = encode_reply(self.controller.handle(request, self._clock(), client))
        with self._lock:  # status() reflects every command whose reply has been sent
            self._status = self.controller.status()
        self._cache.put(replier, request.id, body[0], data)
        return envelope, data

    def _repeated(self, replier: ClientId, request_id: str, body: bytes) -> bytes | None:
        """The reply to a request whose id ``replier`` used before: the cached one for the
        same bytes (a retry), ``id reused`` for others; None for a new id."""
        answered = self._cache.get(replier, request_id)
        if answered is None:
            return None
        if answered.request == body:
            log.info("repeated request %s: the cached reply", request_id)
            return answered.reply
        log.warning("id %s reused for another request: refused", request_id)
        return encode_reply(Reply.failure(request_id, ErrorCode.BAD_REQUEST, "id reused"))

    def _tick(self, publisher: zmq.Socket[bytes], telemetry: TelemetrySchedule) -> None:
        now_s = self._clock()
        self.controller.tick(now_s)
        status = self.controller.status()
        with self._lock:
            self._status = status
        if self.on_tick is not None:
            self.on_tick(status)
        moving = status.state is BaseState.MOVING
        pose_period_s = (
            self.timing.pose_period_moving_s if moving else self.timing.pose_period_rest_s
        )
        if telemetry.due_pose(now_s, pose_period_s):
            publisher.send_multipart(encode_pose_telemetry(now_s, status.pose))
        if telemetry.due_state(now_s, status, self.timing.state_period_s):
            publisher.send_multipart(encode_state_telemetry(status))


class TelemetrySchedule:
    """When the next pose and state messages are due (times from the server's clock)."""

    def __init__(self) -> None:
        self._last_pose_s = -1e9
        self._last_state_s = -1e9
        self._last_key: tuple[object, ...] | None = None

    def due_pose(self, now_s: float, period_s: float) -> bool:
        if now_s - self._last_pose_s < period_s:
            return False
        self._last_pose_s = now_s
        return True

    def due_state(self, now_s: float, status: Status, period_s: float) -> bool:
        key = (status.state, status.goal_id, status.error)
        if key == self._last_key and now_s - self._last_state_s < period_s:
            return False
        self._last_key, self._last_state_s = key, now_s
        return True
