"""What a run is recorded from: the session (id, date, calibration) and the reconstruction's
output folder (plants, organs, report), read and checked before the database is touched."""

from __future__ import annotations

import datetime as dt
import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fieldapp import __version__
from fieldapp.errors import FieldappError, FormatError, Problem
from fieldapp.results.files import PlantRecord, read_plants_csv, read_report
from fieldapp.results.organ_tables import PLANT_ORGAN_TRAITS, read_table


@dataclass(frozen=True)
class SessionSource:
    """A session as the database keeps it; ``calibration``: the calibration document in force
    (``None`` when the session folder was not given)."""

    session_id: str
    date: dt.date
    folder: Path | None
    calibration: dict[str, Any] | None


@dataclass(frozen=True)
class RunSource:
    """A finished reconstruction: its folder, plants, report, settings and software version."""

    results_dir: Path
    plants: list[PlantRecord]
    report: dict[str, Any]
    settings: dict[str, Any]
    software_version: str
    organs: dict[int, dict[str, Any]] = field(default_factory=dict)
    """Per plant of ``plants.csv``: its organ columns (``leaf_count``, ``leaf_area_cm2``,
    ``stem_diameter_mm``, ``None`` where blank) and ``leaves``, the rows of ``leaves.csv``."""

    @property
    def timings_s(self) -> dict[str, float]:
        timings = self.report.get("timings_s", {})
        if not isinstance(timings, dict):
            return {}
        return {str(k): float(v) for k, v in timings.items() if isinstance(v, int | float)}


def canonical_json(document: Any) -> str:
    return json.dumps(document, sort_keys=True, separators=(",", ":"), allow_nan=False)


def settings_hash(settings: Mapping[str, Any]) -> str:
    """SHA-256 of the settings as canonical JSON (key order and spacing do not matter)."""
    return hashlib.sha256(canonical_json(dict(settings)).encode("utf-8")).hexdigest()


def read_run(
    results_dir: Path,
    settings: Mapping[str, Any] | None = None,
    software_version: str | None = None,
) -> RunSource:
    """Read ``plants.csv`` and ``report.json``. Settings and version default to the report's
    ``settings`` and ``software_version`` fields, then to ``{}`` and this fieldapp's version."""
    if not results_dir.is_dir():
        raise FieldappError(f"{results_dir}: no such results folder")
    plants = read_plants_csv(results_dir / "plants.csv")
    report = read_report(results_dir / "report.json")
    if settings is None:
        reported = report.get("settings")
        settings = reported if isinstance(reported, dict) else {}
    if software_version is None:
        reported_version = report.get("software_version")
        software_version = reported_version if isinstance(reported_version, str) else __version__
    organs = read_organs(results_dir)
    return RunSource(results_dir, plants, report, dict(settings), software_version, organs)


def read_organs(results_dir: Path) -> dict[int, dict[str, Any]]:
    """The organ traits of a results folder, by plant; empty when it has no ``leaves.csv``
    (a run from before organs were measured)."""
    if not (results_dir / "leaves.csv").is_file():
        return {}
    columns = read_table(results_dir / "plants.csv", ("plant",))
    organs: dict[int, dict[str, Any]] = {
        int(row["plant"]): {t: row.get(t) for t in PLANT_ORGAN_TRAITS} | {"leaves": []}
        for row in columns
    }
    for leaf in read_table(results_dir / "leaves.csv", ("plant_id", "leaf_id")):
        plant = int(leaf["plant_id"])
        if plant not in organs:
            raise FormatError(
                [
                    Problem(
                        str(results_dir / "leaves.csv"),
                        "column plant_id",
                        f"plant {plant} is not in plants.csv",
                    )
                ]
            )
        if any(other["leaf_id"] == leaf["leaf_id"] for other in organs[plant]["leaves"]):
            raise FormatError(
                [
                    Problem(
                        str(results_dir / "leaves.csv"),
                        "column leaf_id",
                        f"plant {plant} has leaf {leaf['leaf_id']} twice",
                    )
                ]
            )
        organs[plant]["leaves"].append(leaf)
    return organs


def read_session_source(
    session_dir: Path | None, report: Mapping[str, Any], date: dt.date | None
) -> SessionSource:
    """The session of a run: from its folder when given, else the id in ``report.json``.
    ``date`` overrides the session's own (its ``created`` time, else its first capture's)."""
    if session_dir is None:
        session_id = report.get("session")
        if not isinstance(session_id, str) or not session_id:
            raise FieldappError("report.json names no session: give the session folder")
        if date is None:
            raise FieldappError(f"the date of session {session_id} is unknown: give the date")
        return SessionSource(session_id, date, None, None)
    from fieldapp.io.session import load_session

    session = load_session(session_dir, allow_empty=True)
    return SessionSource(
        session.id,
        date or _session_date(session_dir, session.document),
        session_dir.resolve(),
        session.calibration.to_document(),
    )


def _session_date(folder: Path, document: Any) -> dt.date:
    if document.created is not None:
        return document.created.date()  # type: ignore[no-any-return]
    times = [c.captured_at for c in document.captures if c.captured_at is not None]
    if times:
        return min(times).date()  # type: ignore[no-any-return]
    raise FieldappError(f"{folder}: session.json has no date (created): give the date")
