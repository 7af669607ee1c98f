"""Telemetry subscription: a SUB socket on its own thread, handing each message to callbacks.

Callbacks run on the subscriber thread; a Qt UI connects through psygnal and
``ensure_main_thread`` (see ``BaseClient.pose_received``). Malformed messages are logged and
skipped.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import zmq

from devices.base.keys import ClientKeys, require_loopback_without_keys
from devices.base.protocol import (
    TOPIC_POSE,
    TOPIC_STATE,
    Pose,
    ProtocolError,
    Status,
    decode_telemetry,
)

log = logging.getLogger(__name__)

PoseCallback = Callable[[float, Pose], None]
StateCallback = Callable[[Status], None]


class TelemetrySubscriber:
    """Receives ``pose`` and ``state`` messages until :meth:`close`."""

    def __init__(
        self,
        context: zmq.Context[zmq.Socket[bytes]],
        endpoint: str,
        on_pose: PoseCallback,
        on_state: StateCallback,
        keys: ClientKeys | None = None,
    ) -> None:
        require_loopback_without_keys(endpoint, keys is not None)
        self.endpoint = endpoint
        self._on_pose = on_pose
        self._on_state = on_state
        self._stop = threading.Event()
        sock = context.socket(zmq.SUB)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.MAXMSGSIZE, 65536)
        if keys is not None:
            sock.curve_secretkey = keys.pair.secret.reveal()
            sock.curve_publickey = keys.pair.public
            sock.curve_serverkey = keys.server_public
        sock.setsockopt(zmq.SUBSCRIBE, TOPIC_POSE)
        sock.setsockopt(zmq.SUBSCRIBE, TOPIC_STATE)
        sock.connect(endpoint)
        self._thread = threading.Thread(
            target=self._run, args=(sock,), name="base-telemetry", daemon=True
        )
        self._thread.start()

    def _run(self, sock: zmq.Socket[bytes]) -> None:
        try:
            while not self._stop.is_set():
                if sock.poll(timeout=100) == 0:
                    continue
                self._dispatch(sock.recv_multipart())
        finally:
            sock.close(linger=0)

    def _dispatch(self, frames: list[bytes]) -> None:
        try:
            message = decode_telemetry(frames)
        except ProtocolError as error:
            log.warning("malformed telemetry skipped: %s", error.message)
            return
        try:
            if isinstance(message, Status):
                self._on_state(message)
            else:
                self._on_pose(*message)
        except Exception:  # a listener's bug must not end the subscription
            log.exception("telemetry listener failed")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
