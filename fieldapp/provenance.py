"""Where a result came from, computed once for every output: the devices that captured the
session (simulated, real, imported, or unknown), the calibration the reconstruction used, the
software that ran and a hash of the reconstruction settings.

:func:`provenance_of` is called where a reconstruction's outputs are written (``fieldapp
reconstruct``, the GUI's child process, batch); ``report.json`` carries the document under
``provenance``, ``provenance.json`` beside the CSVs repeats it, the results database keeps it
per run, and :func:`summary_line` is the one line the HTML report and the results panel show.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import logging
import subprocess
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from fieldapp import __version__
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration, load_calibration
from fieldapp.io.session import Session
from fieldapp.results.sources import canonical_json, settings_hash

log = logging.getLogger(__name__)

PROVENANCE_FORMAT = "fieldapp-provenance/1"
SECTIONS = ("depth_camera", "view_step", "stations", "ground")
GIT_TIMEOUT_S = 2.0


@dataclass(frozen=True)
class RunProvenance:
    """A reconstruction's provenance: ``document`` (what the files carry) and the ``settings``
    it was run with (as JSON), which ``report.json`` keeps beside it."""

    document: dict[str, Any]
    settings: dict[str, Any]


def provenance_of(session: Session, settings: BaseModel | Mapping[str, Any]) -> RunProvenance:
    """The provenance of reconstructing ``session`` with ``settings`` (the model, or already
    dumped as JSON)."""
    settings_json = (
        settings.model_dump(mode="json") if isinstance(settings, BaseModel) else dict(settings)
    )
    document = {
        "format": PROVENANCE_FORMAT,
        "session": {"id": session.id, "folder": str(session.folder.resolve())},
        "source": source_of(session),
        "calibration": calibration_of(session),
        "software": software(),
        "settings_sha256": settings_hash(settings_json),
        "created": dt.datetime.now().astimezone().isoformat(timespec="seconds"),
    }
    return RunProvenance(document, settings_json)


# --- the devices ------------------------------------------------------------------------


def source_of(session: Session) -> dict[str, Any]:
    """How the session was captured: ``kind`` ``simulated``, ``real``, ``mixed``,
    ``imported`` or ``unknown``, a ``detail`` line, and per device when a mission plan says."""
    extra = session.document.model_extra or {}
    simulated = extra.get("simulated")
    if isinstance(simulated, dict):
        about = ", ".join(f"{k} {v}" for k, v in simulated.items() if k in ("scene", "seed", "day"))
        return {
            "kind": "simulated",
            "detail": f"fieldapp simulate ({about})",
            "simulated": simulated,
        }
    imported = extra.get("imported")
    if isinstance(imported, dict):
        detail = f"imported ({imported.get('by', '?')}) from {imported.get('from', '?')}"
        return {"kind": "imported", "detail": detail, "imported": imported}
    if "mission" in extra:
        return _mission_source(session.folder)
    return {"kind": "unknown", "detail": "session.json does not say how it was captured"}


def _mission_source(folder: Path) -> dict[str, Any]:
    from fieldapp.mission.folder import PLAN_FILE
    from fieldapp.mission.plan import load_plan

    try:
        devices = load_plan(folder / PLAN_FILE).devices
    except FieldappError as error:
        line = str(error).splitlines()[0]
        return {"kind": "unknown", "detail": f"mission without a readable plan ({line})"}
    simulated = {
        "camera": devices.camera_backend in ("sim", "replay"),
        "table": devices.table_port is None,
        "base": devices.base_endpoint is None,
    }
    kind = (
        "simulated" if all(simulated.values()) else "mixed" if any(simulated.values()) else "real"
    )
    named = {
        "camera": devices.camera_backend,
        "table": devices.table_port or "simulated",
        "base": devices.base_endpoint or "simulated",
    }
    detail = "mission: " + ", ".join(f"{k} {v}" for k, v in named.items())
    return {"kind": kind, "detail": detail, "devices": named}


# --- the calibration ----------------------------------------------------------------------


def calibration_of(session: Session) -> dict[str, Any]:
    """The calibration the reconstruction used (the session's ``calibration.json``): its path
    and sha256, each section ``nominal`` or calibrated on a date, ``kind`` ``calibrated``,
    ``partly calibrated`` or ``nominal``, and the rig's file when a mission plan names it."""
    path = (session.folder / session.document.calibration).resolve()
    sections = {
        name: _section_state(getattr(session.calibration, name))
        for name in SECTIONS
        if getattr(session.calibration, name) is not None
    }
    dates = [s["date"] for s in sections.values() if isinstance(s, dict) and s.get("date")]
    calibrated = sum(isinstance(s, dict) for s in sections.values())
    kind = (
        "nominal"
        if calibrated == 0
        else "calibrated"
        if calibrated == len(sections)
        else "partly calibrated"
    )
    document: dict[str, Any] = {
        "kind": kind,
        "file": str(path),
        "sha256": _file_sha256(path),
        "date": max(dates) if dates else None,
        "sections": sections,
    }
    rig = _rig_file(session)
    if rig is not None:
        document["rig_file"] = rig
    return document


def _section_state(section: Any) -> dict[str, Any] | str:
    done = getattr(section, "calibrated", None) or getattr(section, "refined_with_stations", None)
    if not done:
        return "nominal"
    return {k: done[k] for k in ("date", "software", "method", "rig_serial") if k in done}


def _rig_file(session: Session) -> dict[str, Any] | None:
    """The rig's calibration file a mission plan names: path, sha256 now, and whether the
    session's copy still holds the same calibration (``None`` when it is gone)."""
    from fieldapp.mission.folder import PLAN_FILE
    from fieldapp.mission.plan import load_plan

    if not (session.folder / PLAN_FILE).is_file():
        return None
    try:
        named = load_plan(session.folder / PLAN_FILE).calibration
    except FieldappError:
        return None
    if named is None:
        return None
    entry: dict[str, Any] = {"path": str(named), "sha256": _file_sha256(named), "same": None}
    try:
        rig: Calibration = load_calibration(named)
    except (FieldappError, OSError):
        return entry
    entry["same"] = canonical_json(rig.to_document()) == canonical_json(
        session.calibration.to_document()
    )
    return entry


def _file_sha256(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


# --- the software -------------------------------------------------------------------------


@lru_cache(maxsize=1)
def software() -> dict[str, Any]:
    """``{"name": "fieldapp", "version": ..., "commit": ..., "modified": ...}``; the commit
    (and whether the checkout had uncommitted changes) from the git checkout it runs from (with
    git installed) or, in the bundle, from its ``BUILD-INFO``; else ``None``."""
    root = Path(__file__).resolve().parents[1]
    commit, modified = None, None
    if getattr(sys, "frozen", False):  # the bundle: its build wrote the commit beside it
        commit, modified = bundle_commit(Path(sys.executable).parent / "BUILD-INFO")
    elif (root / ".git").exists():
        commit = _git(root, "rev-parse", "--short=12", "HEAD")
        if commit is not None:
            modified = _git(root, "status", "--porcelain", "--untracked-files=no") not in ("", None)
    return {"name": "fieldapp", "version": __version__, "commit": commit, "modified": modified}


def bundle_commit(build_info: Path) -> tuple[str | None, bool | None]:
    """(commit, modified) from a bundle's ``BUILD-INFO`` (``packaging/build.sh`` writes a line
    ``commit <hash>``, then `` modified`` when the tree had uncommitted changes); ``(None,
    None)`` when the file or the line is missing or says ``unknown``."""
    try:
        lines = build_info.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None, None
    for line in lines:
        words = line.split()
        if len(words) >= 2 and words[0] == "commit" and words[1] != "unknown":
            return words[1], "modified" in words[2:]
    return None, None


def _git(root: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(
            ["git", "-C", str(root), *args],
            capture_output=True,
            text=True,
            timeout=GIT_TIMEOUT_S,
            check=True,
        )
    except (OSError, subprocess.SubprocessError) as error:
        log.debug("git %s: %s", args[0], error)
        return None
    return done.stdout.strip()


# --- presenting it ------------------------------------------------------------------------


def summary_line(document: dict[str, Any] | None) -> str:
    """One line: ``Simulated devices · calibration: nominal (sha256 1a2b3c4d) · fieldapp 0.1.0
    (commit abc) · settings a1b2c3d4``."""
    if not document:
        return "Provenance unknown (results written before fieldapp recorded it)"
    source = document.get("source") or {}
    calibration = document.get("calibration") or {}
    software_ = document.get("software") or {}
    parts = [
        _SOURCE_WORDS.get(str(source.get("kind")), "Unknown devices"),
        "calibration: " + _calibration_words(calibration),
        f"fieldapp {software_.get('version', '?')}" + _commit_words(software_),
        f"settings {str(document.get('settings_sha256') or '?')[:8]}",
    ]
    return " · ".join(parts)


_SOURCE_WORDS = {
    "simulated": "Simulated devices",
    "real": "Real devices",
    "mixed": "Real and simulated devices",
    "imported": "Imported data",
    "unknown": "Unknown devices",
}


def _calibration_words(calibration: dict[str, Any]) -> str:
    kind = str(calibration.get("kind", "unknown"))
    words = kind if kind != "calibrated" else "rig file"
    if calibration.get("date"):
        words += f" {str(calibration['date'])[:10]}"
    if calibration.get("sha256"):
        words += f" (sha256 {str(calibration['sha256'])[:8]})"
    return words


def _commit_words(software_: dict[str, Any]) -> str:
    commit = software_.get("commit")
    if not commit:
        return ""
    return f" ({commit}{', modified' if software_.get('modified') else ''})"


def _section_words(state: Any) -> str:
    if isinstance(state, dict):
        return f"calibrated {state.get('date', '?')}"
    return str(state)


def details_text(document: dict[str, Any] | None) -> str:
    """Several lines for a tooltip: the source, the calibration file, sections and rig file,
    the software and the settings hash in full."""
    if not document:
        return summary_line(document)
    source = document.get("source") or {}
    calibration = document.get("calibration") or {}
    sections = calibration.get("sections") or {}
    lines = [
        f"data: {source.get('detail', 'unknown')}",
        f"calibration: {calibration.get('file', '?')}",
        f"  sha256 {calibration.get('sha256') or '?'}",
        *(f"  {name}: {_section_words(state)}" for name, state in sections.items()),
    ]
    rig = calibration.get("rig_file")
    if isinstance(rig, dict):
        same = {True: "same as the session's", False: "changed since", None: "not readable"}
        lines.append(f"  rig file {rig.get('path')}: {same.get(rig.get('same'), '?')}")
    software_ = document.get("software") or {}
    lines.append(f"software: fieldapp {software_.get('version', '?')}{_commit_words(software_)}")
    lines.append(f"settings sha256 {document.get('settings_sha256', '?')}")
    return "\n".join(lines)
