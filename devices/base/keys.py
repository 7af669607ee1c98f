"""CURVE keys for the base link, and the loopback-only rule for running without them.

Key files use pyzmq's certificate format (``zmq.auth``): ``NAME.key`` holds the public key,
``NAME.key_secret`` the pair; secret files are created with mode 0600. Folder layout:

* on the base (``fieldapp sim-base --keys DIR`` or the ROS bridge): ``DIR/base.key_secret`` and
  ``DIR/authorized_clients/*.key`` (the public keys of the workstations allowed to drive);
* on the workstation (``fieldapp base --keys DIR``): ``DIR/client.key_secret`` and
  ``DIR/base.key`` (the base's public key).

``fieldapp keys generate DIR --name base`` and ``... --name client`` make the pairs; copy
``client.key`` into the base's ``authorized_clients/`` and ``base.key`` to the workstation.
Secret keys are wrapped in :class:`SecretKey`, whose repr never shows them.
"""

from __future__ import annotations

import ipaddress
import os
import re
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import zmq
import zmq.auth

from devices.base.errors import InsecureEndpoint, KeyFileError

SERVER_KEY_NAME = "base"
CLIENT_KEY_NAME = "client"
AUTHORIZED_CLIENTS_DIR = "authorized_clients"
_NAME_PATTERN = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


class SecretKey:
    """A Z85 CURVE secret key that never shows itself in logs or reprs."""

    __slots__ = ("_z85",)

    def __init__(self, z85: bytes) -> None:
        self._z85 = z85

    def reveal(self) -> bytes:
        """The key itself, only to hand to a socket option."""
        return self._z85

    def __repr__(self) -> str:
        return "SecretKey(<hidden>)"

    __str__ = __repr__


@dataclass(frozen=True)
class KeyPair:
    public: bytes
    secret: SecretKey


@dataclass(frozen=True)
class ServerKeys:
    """The base's key pair and the folder of authorised client public keys."""

    pair: KeyPair
    authorized_dir: Path

    @classmethod
    def from_dir(cls, directory: Path) -> ServerKeys:
        authorized = directory / AUTHORIZED_CLIENTS_DIR
        if not authorized.is_dir():
            raise KeyFileError(f"{authorized}: authorised client keys folder is missing")
        return cls(load_key_pair(directory / f"{SERVER_KEY_NAME}.key_secret"), authorized)


@dataclass(frozen=True)
class ClientKeys:
    """The workstation's key pair and the base's public key."""

    pair: KeyPair
    server_public: bytes

    @classmethod
    def from_dir(cls, directory: Path, name: str = CLIENT_KEY_NAME) -> ClientKeys:
        pair = load_key_pair(directory / f"{name}.key_secret")
        return cls(pair, load_public_key(directory / f"{SERVER_KEY_NAME}.key"))


def _key_text(banner: str, public: bytes, secret: bytes | None) -> str:
    lines = [f"#   ****  Generated on {datetime.now()} by fieldapp  ****", f"#   {banner}", ""]
    lines += ["metadata", "curve", f'    public-key = "{public.decode("ascii")}"']
    if secret is not None:
        lines.append(f'    secret-key = "{secret.decode("ascii")}"')
    return "\n".join(lines) + "\n"


def _write_new(path: Path, text: str, mode: int) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    with os.fdopen(fd, "w", encoding="ascii") as file:
        file.write(text)
    os.chmod(path, mode)  # the umask may have removed bits, never added them


def generate_key_pair(directory: Path, name: str) -> tuple[Path, Path]:
    """Write ``NAME.key`` (0644) and ``NAME.key_secret`` (0600); returns (public, secret) paths.

    Refuses to overwrite existing files (:class:`KeyFileError`).
    """
    if not _NAME_PATTERN.match(name):
        raise KeyFileError(f"key name {name!r}: use letters, digits, '.', '_' or '-'")
    directory.mkdir(parents=True, exist_ok=True)
    public_path = directory / f"{name}.key"
    secret_path = directory / f"{name}.key_secret"
    for path in (public_path, secret_path):
        if path.exists():
            raise KeyFileError(f"{path}: already exists, not overwriting a key")
    public, secret = zmq.curve_keypair()
    _write_new(secret_path, _key_text("CURVE secret key: keep private", public, secret), 0o600)
    _write_new(public_path, _key_text("CURVE public key", public, None), 0o644)
    return public_path, secret_path


def _load(path: Path) -> tuple[bytes, bytes | None]:
    try:
        public, secret = zmq.auth.load_certificate(path)
    except (OSError, ValueError) as error:
        raise KeyFileError(f"{path}: cannot read a CURVE key ({error})") from None
    if len(public) != 40:
        raise KeyFileError(f"{path}: public-key is not a 40-character Z85 key")
    return public, secret


def load_public_key(path: Path) -> bytes:
    return _load(path)[0]


def load_key_pair(path: Path) -> KeyPair:
    public, secret = _load(path)
    if secret is None or len(secret) != 40:
        raise KeyFileError(f"{path}: secret-key missing or not a 40-character Z85 key")
    return KeyPair(public, SecretKey(secret))


def is_loopback(endpoint: str) -> bool:
    """True for ``inproc://``, ``ipc://`` and ``tcp://`` on 127.0.0.0/8, ``::1`` or localhost."""
    scheme, _, rest = endpoint.partition("://")
    if scheme in ("inproc", "ipc"):
        return True
    if scheme != "tcp":
        return False
    host = rest.rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def require_loopback_without_keys(endpoint: str, has_keys: bool) -> None:
    """Raise :class:`InsecureEndpoint` for a non-loopback ``endpoint`` without CURVE keys."""
    if not has_keys and not is_loopback(endpoint):
        raise InsecureEndpoint(
            f"{endpoint}: refusing a non-loopback address without CURVE keys "
            "(give --keys DIR; see 'fieldapp keys generate')"
        )
