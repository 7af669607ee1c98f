"""Reading the files a session names: regular files only, bounded in size, never blocking.

A FIFO in place of a frame would block ``open`` forever, a character device such as
``/dev/zero`` would be read forever, and a symbolic link loop raises from deep inside
:mod:`pathlib`. :func:`read_regular_file` refuses all of them before reading a byte, and reads
at most a stated number of bytes.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

_CHUNK_BYTES = 1 << 20


class UnreadableFile(Exception):
    """A file cannot be read as a regular file; the text says why, for a :class:`Problem`."""


def _kind(mode: int) -> str | None:
    """What a non-regular file is ("a FIFO", ...), or ``None`` for a regular file."""
    kinds = [
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ]
    for test, name in kinds:
        if test(mode):
            return name
    return None if stat.S_ISREG(mode) else "not a regular file"


def _os_reason(path: Path, error: OSError) -> str:
    if error.errno == errno.ELOOP:
        return "is a symbolic link loop"
    if isinstance(error, FileNotFoundError):
        return "is a symbolic link to a missing file" if path.is_symlink() else "file is missing"
    if isinstance(error, PermissionError):
        return "cannot read: permission denied"
    return f"cannot read: {error.strerror or error}"


def _check_regular(mode: int) -> None:
    kind = _kind(mode)
    if kind is not None:
        raise UnreadableFile(f"is {kind}, not a regular file")


def read_regular_file(path: Path, max_bytes: int, what: str = "file") -> bytes:
    """The bytes of ``path`` when it is a regular file (links followed) of at most
    ``max_bytes``; raises :class:`UnreadableFile` otherwise, without blocking.

    ``what`` names the kind of file in the size message ("a session file", "an image").
    """
    try:
        info = os.stat(path)
        _check_regular(info.st_mode)  # before opening: opening a serial device resets it
        if info.st_size > max_bytes:
            raise UnreadableFile(f"is {info.st_size} bytes, more than {what} can be ({max_bytes})")
        # O_NONBLOCK: a FIFO swapped in after the check opens at once instead of waiting for a
        # writer; fstat then refuses it.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC)
    except OSError as error:
        raise UnreadableFile(_os_reason(path, error)) from None
    try:
        _check_regular(os.fstat(fd).st_mode)
        return _read_at_most(fd, max_bytes, what)
    except OSError as error:
        raise UnreadableFile(_os_reason(path, error)) from None
    finally:
        os.close(fd)


def _read_at_most(fd: int, max_bytes: int, what: str) -> bytes:
    chunks: list[bytes] = []
    total = 0
    while True:
        chunk = os.read(fd, min(_CHUNK_BYTES, max_bytes + 1 - total))
        if not chunk:
            return b"".join(chunks)
        chunks.append(chunk)
        total += len(chunk)
        if total > max_bytes:
            raise UnreadableFile(f"is more than {what} can be ({max_bytes} bytes)")


def resolves_inside(path: Path, root: Path) -> bool | None:
    """Whether ``path`` (links followed) stays inside ``root`` (already resolved); ``None``
    when it cannot be resolved (a link loop: reading it reports that)."""
    try:
        return path.resolve().is_relative_to(root)
    except (OSError, RuntimeError):  # Python 3.11 raises RuntimeError on a link loop
        return None
