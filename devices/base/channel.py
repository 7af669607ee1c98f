"""Reliable request-reply to the base: Lazy Pirate over a REQ socket, with a handshake monitor.

The request side of :class:`~devices.base.transport.ZmqTransport`. Each attempt waits the
policy's ``timeout_s`` for the reply; on silence the socket is closed and reopened and the SAME
request (same id) is sent again, at most ``retries`` more times, then :class:`BaseOffline`.
:meth:`RequestChannel.close` ends a request still waiting (:class:`LinkClosed`, within a poll
slice: the application never waits out a retry budget to close) and refuses later ones. A
send never blocks: with no peer to queue for (an in-process base whose socket is gone:
``inproc://`` keeps no pipe, unlike TCP) the try fails at once. A reply whose id is not the
request's is discarded as no reply. The socket's monitor reports the CURVE handshake: a refused
key raises :class:`BaseAuthRejected` at once (the base sends nothing else to a stranger), never
"offline".
"""

from __future__ import annotations

import itertools
import logging
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zmq
from zmq.utils.monitor import parse_monitor_message

from devices.base.errors import BaseAuthRejected, BaseError, BaseOffline, LinkClosed
from devices.base.keys import ClientKeys, require_loopback_without_keys
from devices.base.protocol import ProtocolError, Reply, decode_reply

log = logging.getLogger(__name__)

_monitor_ids = itertools.count()

POLL_SLICE_S = 0.05

_KEY_HINT = "is base.key the base's public key, and do both ends use CURVE?"
_HANDSHAKE_FAILURES: dict[int, str] = {
    zmq.EVENT_HANDSHAKE_FAILED_AUTH: "the base refused this client's key: is client.key in the "
    "base's authorized_clients folder?",
    zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL: f"the security handshake failed: {_KEY_HINT}",
    zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL: f"the security handshake failed: {_KEY_HINT}",
}


@dataclass(frozen=True)
class RetryPolicy:
    timeout_s: float = 0.5
    retries: int = 2


class RequestChannel:
    """One REQ connection to a base's command socket; thread-safe (one request at a time)."""

    def __init__(
        self,
        context: zmq.Context[zmq.Socket[bytes]],
        endpoint: str,
        keys: ClientKeys | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``clock`` times each try's wait (a fake one in tests); the socket is polled at
        least every ``POLL_SLICE_S`` of real time to look at it."""
        require_loopback_without_keys(endpoint, keys is not None)
        self.endpoint = endpoint
        self._context = context
        self._keys = keys
        self._clock = clock
        self._lock = threading.Lock()
        self._socket: zmq.Socket[bytes] | None = None
        self._monitor: zmq.Socket[bytes] | None = None
        self._failures = 0
        self._closed = threading.Event()
        self._last_failure: BaseError | None = None
        self.routing_id = b"fieldapp-" + secrets.token_hex(8).encode()
        """Kept across reconnections: the base knows this client (its goal, its replies)."""

    def request(self, request_id: str, data: bytes, policy: RetryPolicy) -> Reply:
        """Send ``data`` and return the reply with id ``request_id`` (Lazy Pirate)."""
        failures_seen = self._failures
        with self._lock:
            if self._closed.is_set():
                raise self._closed_error(request_id)
            if self._failures != failures_seen and self._last_failure is not None:
                raise type(self._last_failure)(str(self._last_failure))
            try:
                return self._request_locked(request_id, data, policy)
            except BaseError as error:
                self._failures += 1
                self._last_failure = error
                self._close_socket()
                raise

    def _request_locked(self, request_id: str, data: bytes, policy: RetryPolicy) -> Reply:
        attempts = policy.retries + 1
        for attempt in range(1, attempts + 1):
            if self._socket is None:
                self._open_socket()
            reply = self._attempt(request_id, data, policy.timeout_s)
            if reply is not None:
                return reply
            log.warning(
                "no reply to %s (attempt %d of %d): reconnecting", request_id, attempt, attempts
            )
            self._close_socket()
        total_s = attempts * policy.timeout_s
        raise BaseOffline(
            f"base at {self.endpoint} is offline: no reply in {attempts} tries over {total_s:.1f} s"
        )

    def _attempt(self, request_id: str, data: bytes, timeout_s: float) -> Reply | None:
        sock, monitor = self._socket, self._monitor
        if sock is None or monitor is None:
            raise RuntimeError("request channel is closed")
        try:
            sock.send(data, zmq.NOBLOCK)
        except zmq.Again:  # no peer to queue for: an inproc:// base whose socket has gone
            log.warning("%s: nowhere to send %s", self.endpoint, request_id)
            return None
        poller = zmq.Poller()
        poller.register(sock, zmq.POLLIN)
        poller.register(monitor, zmq.POLLIN)
        deadline_s = self._clock() + timeout_s
        while (remaining_s := deadline_s - self._clock()) > 0:
            if self._closed.is_set():
                raise self._closed_error(request_id)
            wait_s = min(remaining_s, POLL_SLICE_S)
            events = dict(poller.poll(timeout=max(1, round(wait_s * 1000))))
            if monitor in events:
                self._read_monitor(monitor)
            if sock in events:
                return self._read_reply(sock.recv(), request_id)
        return None

    def _read_reply(self, raw: bytes, request_id: str) -> Reply | None:
        try:
            reply = decode_reply(raw)
        except ProtocolError as error:
            log.warning("malformed reply to %s discarded: %s", request_id, error.message)
            return None
        if reply.id != request_id:
            log.warning("reply for %r does not match request %s: discarded", reply.id, request_id)
            return None
        return reply

    def _read_monitor(self, monitor: zmq.Socket[bytes]) -> None:
        while True:
            try:
                event = parse_monitor_message(monitor.recv_multipart(zmq.NOBLOCK))
            except zmq.Again:
                return
            reason = _HANDSHAKE_FAILURES.get(int(event["event"]))
            if reason is not None:
                raise BaseAuthRejected(
                    f"authentication rejected by the base at {self.endpoint}: {reason} "
                    f"(zmq code {event['value']})"
                )

    def _open_socket(self) -> None:
        sock = self._context.socket(zmq.REQ)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.ROUTING_ID, self.routing_id)
        if self._keys is not None:
            sock.curve_secretkey = self._keys.pair.secret.reveal()
            sock.curve_publickey = self._keys.pair.public
            sock.curve_serverkey = self._keys.server_public
        address = f"inproc://base-channel-monitor-{next(_monitor_ids)}"
        sock.monitor(address, zmq.EVENT_ALL)
        monitor = self._context.socket(zmq.PAIR)
        monitor.setsockopt(zmq.LINGER, 0)
        monitor.connect(address)
        sock.connect(self.endpoint)
        self._socket, self._monitor = sock, monitor

    def _close_socket(self) -> None:
        if self._socket is not None:
            self._socket.disable_monitor()
            self._socket.close(linger=0)
        if self._monitor is not None:
            self._monitor.close(linger=0)
        self._socket = self._monitor = None

    def _closed_error(self, request_id: str) -> LinkClosed:
        return LinkClosed(
            f"the link to the base at {self.endpoint} was closed: {request_id} has no reply"
        )

    def close(self) -> None:
        """End a request still waiting for its reply (it raises :class:`LinkClosed`), release
        the sockets, refuse every later request. Idempotent."""
        self._closed.set()
        with self._lock:
            self._close_socket()
