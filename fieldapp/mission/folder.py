"""A mission's session folder: the plan beside the session, what is missing, how it ended.

Besides what the session format defines (``session.json``, ``calibration.json``, images), a
mission folder holds ``mission-plan.yaml`` (the plan as run, written before anything else, so
any folder with a session can be resumed) and ``mission-status.json`` (the last state, what is
missing, and the fault with its advice; ``running`` after a crash). A capture is listed in
``session.json`` only once its files are complete (:class:`~fieldapp.io.writer.SessionWriter`);
temporary files a crash left behind are removed on resume.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration
from fieldapp.io.durable import write_json_durably
from fieldapp.io.session import SESSION_FILE, now_iso
from fieldapp.io.writer import SessionWriter
from fieldapp.mission.events import MissionResult
from fieldapp.mission.plan import MissionPlan, load_plan, save_plan

log = logging.getLogger(__name__)

PLAN_FILE = "mission-plan.yaml"
STATUS_FILE = "mission-status.json"


def start_session(folder: Path, plan: MissionPlan, calibration: Calibration) -> SessionWriter:
    """Make ``folder`` a new mission session: plan first, then calibration and session.json.

    Refuses a folder that already holds a session (resume it instead).
    """
    if (folder / SESSION_FILE).exists():
        raise FieldappError(
            f"{folder}: already holds a session; resume it (`fieldapp mission resume {folder}`) "
            "or choose a new folder"
        )
    if folder.exists() and not folder.is_dir():
        raise FieldappError(f"{folder}: exists and is not a folder")
    folder.mkdir(parents=True, exist_ok=True)
    save_plan(plan, folder / PLAN_FILE)
    session_id = f"{plan.name}-{now_iso()[:19].replace(':', '')}"
    return SessionWriter.create(
        folder, session_id, calibration, extra={"mission": plan.name, "plan": plan.session_plan()}
    )


def read_plan(folder: Path) -> MissionPlan:
    """The plan a mission folder was started with."""
    if not (folder / PLAN_FILE).exists():
        raise FieldappError(
            f"{folder}: not a mission folder (no {PLAN_FILE}); start one with "
            f"`fieldapp mission run --out {folder}`"
        )
    return load_plan(folder / PLAN_FILE)


def reopen_session(folder: Path, calibration: Callable[[], Calibration]) -> SessionWriter:
    """The session of a started mission, ready to add what is missing. A mission killed before
    its session.json landed gets it now (with ``calibration()``)."""
    remove_stray_temporaries(folder)
    if not (folder / SESSION_FILE).exists():
        plan = read_plan(folder)
        log.info("%s: the mission never wrote its session; starting it now", folder)
        session_id = f"{plan.name}-{now_iso()[:19].replace(':', '')}"
        return SessionWriter.create(
            folder,
            session_id,
            calibration(),
            extra={"mission": plan.name, "plan": plan.session_plan()},
        )
    return SessionWriter.open(folder)


def missing_keys(plan: MissionPlan, writer: SessionWriter) -> list[tuple[int, int]]:
    """Planned (station, view) pairs the session has no capture of, in plan order."""
    present = {(c.station, c.view) for c in writer.session.captures}
    return [key for key in plan.capture_keys() if key not in present]


def remove_stray_temporaries(folder: Path) -> int:
    """Delete the durable writer's temporary files (``.NAME.HEX.tmp``) a crash left; returns
    how many."""
    count = 0
    for path in folder.rglob(".*.tmp"):
        if path.is_file():
            path.unlink()
            count += 1
    if count:
        log.info("%s: removed %d temporary files left by an interrupted write", folder, count)
    return count


def write_status(folder: Path, state: str, result: MissionResult | None = None) -> None:
    """Record the mission's state (and how it ended) in ``mission-status.json``."""
    document: dict[str, Any] = {"state": state, "updated": now_iso()}
    if result is not None:
        document.update(
            outcome=result.outcome.value,
            captured=result.captured,
            missing=[list(key) for key in result.missing],
            message=result.message,
            fault=asdict(result.fault) if result.fault else None,
        )
    write_json_durably(folder / STATUS_FILE, document)
