"""How the base driver reaches a base: the :class:`BaseTransport` it is handed, and its makers.

:class:`~devices.base.client.BaseClient` speaks fieldapp-base/1 (ids, sessions, goals,
heartbeats) and never opens a socket: it is given a transport that carries one request to its
reply (Lazy Pirate: wait ``policy.timeout_s``, reconnect, resend the same bytes, at most
``policy.retries`` more times, then :class:`BaseOffline`) and delivers telemetry to callbacks.

:class:`ZmqTransport` is the one implementation: a REQ :class:`RequestChannel` (with the CURVE
handshake monitor) and a SUB :class:`TelemetrySubscriber` on a ZeroMQ context it is handed.

- Over the network (``tcp://``, CURVE with keys, loopback only without): the transport owns
  its context and terminates it on :meth:`ZmqTransport.close`.
- In process (``inproc://``): the context is the one the in-process base binds on
  (``SimulatedBase(..., context=...)``), shared and left open. The same sockets, envelopes,
  retries and server loop run as over TCP, only without the kernel, ports or CURVE; the tests
  use it wherever the network itself is not what they test.

:func:`open_transport` picks between them from the endpoint.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable
from typing import Protocol

import zmq

from devices.base.channel import RequestChannel, RetryPolicy
from devices.base.errors import BaseError
from devices.base.keys import ClientKeys, require_loopback_without_keys
from devices.base.protocol import Reply
from devices.base.telemetry import PoseCallback, StateCallback, TelemetrySubscriber

log = logging.getLogger(__name__)

Context = zmq.Context[zmq.Socket[bytes]]

INPROC_SCHEME = "inproc://"
_inproc_ids = itertools.count(1)


class BaseTransport(Protocol):
    """What :class:`~devices.base.client.BaseClient` needs to reach a base."""

    @property
    def endpoint(self) -> str:
        """Where requests go, for messages."""
        ...

    @property
    def carries_telemetry(self) -> bool:
        """True when :meth:`subscribe` can deliver telemetry."""
        ...

    def request(self, request_id: str, data: bytes, policy: RetryPolicy) -> Reply:
        """Send ``data`` and return the reply whose id is ``request_id``, reconnecting and
        resending on silence; raise :class:`BaseOffline` after the retries,
        :class:`BaseAuthRejected` when the base refuses the handshake. Thread-safe."""
        ...

    def subscribe(self, on_pose: PoseCallback, on_state: StateCallback) -> None:
        """Deliver ``pose`` and ``state`` telemetry to the callbacks (on a transport thread)
        until :meth:`close`."""
        ...

    def close(self) -> None:
        """Release the sockets (the base is not told); a request still waiting for its reply
        raises :class:`LinkClosed` at once, later ones too. Thread-safe, idempotent."""
        ...


class ZmqTransport:
    """fieldapp-base/1's sockets on a ZeroMQ ``context``, closed with it when ``owns_context``."""

    def __init__(
        self,
        context: Context,
        endpoint: str,
        telemetry_endpoint: str | None = None,
        keys: ClientKeys | None = None,
        *,
        owns_context: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``clock`` times each request's tries (a fake one in tests)."""
        if telemetry_endpoint is not None:
            require_loopback_without_keys(telemetry_endpoint, keys is not None)
        self._channel = RequestChannel(context, endpoint, keys, clock)
        self._context = context
        self._owns_context = owns_context
        self._keys = keys
        self.telemetry_endpoint = telemetry_endpoint
        self._subscriber: TelemetrySubscriber | None = None

    @property
    def endpoint(self) -> str:
        return self._channel.endpoint

    @property
    def carries_telemetry(self) -> bool:
        return self.telemetry_endpoint is not None

    @property
    def routing_id(self) -> bytes:
        """The command socket's identity, kept across reconnections (the base knows the
        client by it: its goal, its cached replies)."""
        return self._channel.routing_id

    def request(self, request_id: str, data: bytes, policy: RetryPolicy) -> Reply:
        return self._channel.request(request_id, data, policy)

    def subscribe(self, on_pose: PoseCallback, on_state: StateCallback) -> None:
        if self.telemetry_endpoint is None:
            raise BaseError(f"{self.endpoint}: this transport was given no telemetry endpoint")
        if self._subscriber is not None:
            raise BaseError(f"{self.telemetry_endpoint}: telemetry is already subscribed")
        self._subscriber = TelemetrySubscriber(
            self._context, self.telemetry_endpoint, on_pose, on_state, self._keys
        )

    def close(self) -> None:
        if self._subscriber is not None:
            self._subscriber.close()
            self._subscriber = None
        self._channel.close()
        if self._owns_context:
            self._context.term()


def open_transport(
    endpoint: str,
    telemetry_endpoint: str | None = None,
    *,
    keys: ClientKeys | None = None,
    context: Context | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> ZmqTransport:
    """The transport to a base at ``endpoint`` (and its telemetry, if given).

    ``context``: the one the base binds on, required for ``inproc://`` (an in-process base);
    otherwise the transport makes its own. ``clock`` times each request's tries. Raises
    :class:`InsecureEndpoint` for a non-loopback address without ``keys``.
    """
    in_process = [e for e in (endpoint, telemetry_endpoint) if e and e.startswith(INPROC_SCHEME)]
    if context is None and in_process:
        raise BaseError(
            f"{in_process[0]}: an inproc:// endpoint is reachable only through the ZeroMQ "
            "context of the in-process base that binds it (pass context=)"
        )
    own = context is None
    used: Context = zmq.Context() if context is None else context
    try:
        return ZmqTransport(used, endpoint, telemetry_endpoint, keys, owns_context=own, clock=clock)
    except BaseException:
        if own:
            used.term()
        raise


def new_inproc_endpoints(name: str = "base") -> tuple[str, str]:
    """Fresh (command, telemetry) ``inproc://`` endpoints for an in-process base."""
    number = next(_inproc_ids)
    return f"{INPROC_SCHEME}{name}-{number}", f"{INPROC_SCHEME}{name}-{number}-telemetry"
