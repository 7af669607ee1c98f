"""Saving calibration results: provenance on every result, the previous file always kept."""

from __future__ import annotations

import shutil
from datetime import datetime
from pathlib import Path
from typing import Any, cast

from fieldapp import __version__
from fieldapp.io.calibration import Calibration, Provenance
from fieldapp.io.calibration import save_calibration as _save
from fieldapp.io.durable import fsync_folder


def provenance(rig_serial: str | None, **quality: Any) -> Provenance:
    """What a calibration result carries: date, software, rig serial and its quality figures."""
    return cast(
        Provenance,
        {
            "date": datetime.now().astimezone().isoformat(timespec="seconds"),
            "software": f"fieldapp {__version__}",
            "rig_serial": rig_serial or "unknown",
            **quality,
        },
    )


def save_keeping_previous(path: Path, calibration: Calibration) -> Path | None:
    """Write ``calibration`` to ``path`` durably; an existing file is first copied to
    ``<stem>.previous-<time>-<nn>.json`` beside it. Returns that copy's path, if any."""
    previous = None
    if path.exists():
        stamp = datetime.now().strftime("%Y%m%dT%H%M%S")
        count = 1
        previous = path.with_name(f"{path.stem}.previous-{stamp}-01.json")
        while previous.exists():  # never overwrite a kept calibration; names sort by time
            count += 1
            previous = path.with_name(f"{path.stem}.previous-{stamp}-{count:02d}.json")
        shutil.copy2(path, previous)
        fsync_folder(path.parent)
    _save(path, calibration)
    return previous
