"""Crash-safe file writing: temporary file, fsync, rename, fsync of the folder.

After a crash at any point a file under its final name is either the old one or the complete
new one, never half written.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

FSYNC_THREADS = 4
"""Threads waiting on the disk at once in :func:`write_files_durably` (they spend their time
in fsync, not on a core)."""


def write_bytes_durably(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically and durably (creating parent folders)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _synced_temporary(path, data)
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_folder(path.parent)


def write_files_durably(files: Mapping[Path, bytes]) -> None:
    """Write each file (path: data) as :func:`write_bytes_durably` does, in the mapping's
    order, each folder fsynced once after the renames and the files' own fsyncs overlapping
    (:data:`FSYNC_THREADS`): one fsync after another is most of the time of writing a
    reconstruction's twenty files. A crash leaves each file the old one or the new one whole;
    when a file's data cannot be written and synced, none is replaced."""
    for folder in {path.parent for path in files}:
        folder.mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(max(1, min(FSYNC_THREADS, len(files)))) as pool:
        futures = [pool.submit(_synced_temporary, path, data) for path, data in files.items()]
    failed = next((f.exception() for f in futures if f.exception() is not None), None)
    temporaries = [f.result() for f in futures if f.exception() is None]
    try:
        if failed is not None:
            raise failed
        for tmp, path in zip(temporaries, files, strict=True):
            os.replace(tmp, path)
    except BaseException:
        for tmp in temporaries:
            tmp.unlink(missing_ok=True)
        raise
    for folder in dict.fromkeys(path.parent for path in files):
        fsync_folder(folder)


def _synced_temporary(path: Path, data: bytes) -> Path:
    """``data`` written and fsynced to a new temporary file beside ``path``."""
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.tmp"
    # os.open with 0o666 honours the umask (mkstemp would make every file private)
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "wb") as file:
            file.write(data)
            file.flush()
            os.fsync(file.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def write_json_durably(path: Path, document: Any) -> None:
    """Write ``document`` as indented UTF-8 JSON, atomically and durably."""
    write_bytes_durably(path, json_bytes(document))


def json_bytes(document: Any) -> bytes:
    """``document`` as :func:`write_json_durably` writes it: indented UTF-8 JSON, no NaN."""
    text = json.dumps(document, indent=2, allow_nan=False, ensure_ascii=False) + "\n"
    return text.encode("utf-8")


def fsync_folder(folder: Path) -> None:
    """Make a rename or a new entry in ``folder`` durable."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
