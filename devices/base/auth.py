"""Who may drive the base: the authorised client keys, read again when their folder changes.

:class:`AuthorizedKeys` is the credentials provider of the base's ZAP handler (pyzmq's
``ThreadAuthenticator.configure_curve_callback``): every CURVE handshake asks it, and every
refusal is logged with the client's public key. The server also asks it for every request, so
that a key removed from ``authorized_clients/`` stops working on connections already made.
:func:`enforce_zap` makes a socket fail closed: without a ZAP handler, libzmq would accept any
CURVE client.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

import zmq

from devices.base.errors import KeyFileError
from devices.base.keys import load_public_key

log = logging.getLogger(__name__)

ZAP_DOMAIN = "fieldapp-base"
"""The ZAP domain of the base's sockets (the handler answers for this domain only)."""


def enforce_zap(sock: zmq.Socket[bytes]) -> None:
    """Ask ZAP for every CURVE handshake on ``sock`` and refuse it when no handler answers."""
    sock.setsockopt(zmq.ZAP_DOMAIN, ZAP_DOMAIN.encode())
    sock.setsockopt(zmq.ZAP_ENFORCE_DOMAIN, 1)


class AuthorizedKeys:
    """The public keys (Z85) in ``folder/*.key``; :meth:`refresh` re-reads them on a change."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self._lock = threading.Lock()
        self._keys: frozenset[bytes] = frozenset()
        self._signature: tuple[tuple[str, int, int], ...] | None = None
        self.revocations = 0
        """How many times keys were removed: the server then drops every connection."""
        self.refresh()

    def _read_signature(self) -> tuple[tuple[str, int, int], ...]:
        try:
            entries = sorted(self.folder.glob("*.key"))
            return tuple((p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in entries)
        except OSError as error:
            log.error("cannot list authorised keys in %s: %s", self.folder, error)
            return ()

    def refresh(self) -> bool:
        """Re-read the folder if it changed; True when the set of keys changed."""
        signature = self._read_signature()
        if signature == self._signature:
            return False
        keys: set[bytes] = set()
        for name, _mtime, _size in signature:
            try:
                keys.add(load_public_key(self.folder / name))
            except KeyFileError as error:
                log.error("authorised key ignored: %s", error)
        with self._lock:
            removed, added = self._keys - keys, keys - self._keys
            self._keys, self._signature = frozenset(keys), signature
            self.revocations += bool(removed)
        for key in sorted(removed):
            log.warning("client key %s removed from %s: revoked", key.decode(), self.folder)
        for key in sorted(added):
            log.info("client key %s authorised (%s)", key.decode(), self.folder)
        return bool(removed or added)

    def allows(self, public_z85: bytes) -> bool:
        with self._lock:
            return public_z85 in self._keys

    def callback(self, domain: str, key: bytes) -> bool:
        """The ZAP handler's question for each handshake (``key``: Z85 public key)."""
        allowed = domain == ZAP_DOMAIN and self.allows(key)
        if not allowed:
            log.warning(
                "rejected handshake: client key %s is not in %s",
                key.decode("ascii", "replace"),
                self.folder,
            )
        return allowed
