"""The season's results: plots, sessions, reconstruction runs, plants (one id all season) and
their traits, their leaves (by plant and leaf number, so a leaf's growth can be followed), hand
measurements; one SQLite file (WAL, so readers never wait for a writer).

A run is written in one transaction: a crash at any point leaves the database as it was.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import sqlite3
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fieldapp.results.files import ManualRecord, PlantRecord
from fieldapp.results.identity import match_positions
from fieldapp.results.organ_tables import LEAF_TRAITS, PLANT_ORGAN_TRAITS
from fieldapp.results.schema import ResultsDBError, connect, migrate, schema_version
from fieldapp.results.sources import (
    RunSource,
    SessionSource,
    canonical_json,
    read_run,
    read_session_source,
    settings_hash,
)

log = logging.getLogger(__name__)

DEFAULT_MATCH_DISTANCE_M = 0.15


@dataclass(frozen=True)
class RunInfo:
    """A recorded reconstruction run."""

    run_id: int
    plot: str
    session_id: str
    date: dt.date
    status: str
    recorded: str
    results_dir: str | None
    software_version: str
    settings_sha256: str
    plants: int
    message: str
    provenance: dict[str, Any] | None = None
    """The run's provenance document (:mod:`fieldapp.provenance`); ``None`` for a run recorded
    before fieldapp kept it or from results written without it."""


@dataclass(frozen=True)
class Observation:
    """A plant's traits on one date (the latest complete run of that date's session)."""

    plant_id: int
    plant_number: int
    date: dt.date
    session_id: str
    run_id: int
    x_m: float
    y_m: float
    height_cm: float
    width_cm: float


@dataclass(frozen=True)
class LeafObservation:
    """One leaf of a plant on one date: ``traits`` by :data:`LEAF_TRAITS` name."""

    plant_number: int
    leaf_id: int
    date: dt.date
    session_id: str
    run_id: int
    traits: dict[str, float | None]


_LATEST_RUNS = (
    "FROM {table} JOIN runs ON runs.id = {table}.run_id "
    "JOIN sessions ON sessions.id = runs.session_id "
    "JOIN plants ON plants.id = {table}.plant_id "
    "JOIN plots ON plots.id = sessions.plot_id "
    "WHERE plots.name = ? AND runs.id = (SELECT MAX(r.id) FROM runs r "
    "WHERE r.session_id = sessions.id AND r.status = 'complete') "
)
"""The rows of ``{table}`` (traits or leaves) of a plot (the ``?``) in each session's latest
complete run: what the history queries share."""


class ResultsDB:
    """The results database. ``open`` it, use it, ``close`` it (or use it as a context)."""

    def __init__(self, connection: sqlite3.Connection, path: Path) -> None:
        self.connection = connection
        self.path = path

    @classmethod
    def open(cls, path: Path, create: bool = True) -> ResultsDB:
        """Open (creating it and its folder when ``create``) and migrate to the current schema."""
        if not path.exists():
            if not create:
                raise ResultsDBError(f"{path}: no results database (record a run first)")
            path.parent.mkdir(parents=True, exist_ok=True)
        connection = connect(path)
        try:
            migrate(connection, path)
        except BaseException:
            connection.close()
            raise
        return cls(connection, path)

    def close(self) -> None:
        self.connection.close()

    def __enter__(self) -> ResultsDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def schema_version(self) -> int:
        return schema_version(self.connection)

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        self.connection.execute("BEGIN IMMEDIATE")
        try:
            yield self.connection
        except BaseException:
            self.connection.execute("ROLLBACK")
            raise
        self.connection.execute("COMMIT")

    # --- writing ------------------------------------------------------------------------

    def record_run(
        self,
        plot: str,
        session_dir: Path | None,
        results_dir: Path,
        *,
        date: dt.date | None = None,
        settings: Mapping[str, Any] | None = None,
        software_version: str | None = None,
        max_distance_m: float = DEFAULT_MATCH_DISTANCE_M,
    ) -> int:
        """Record a finished reconstruction of a session of ``plot``; returns the run id.

        Each plant gets the season id of the known plant of the plot within ``max_distance_m``
        (one-to-one), or a new one."""
        run = read_run(results_dir, settings, software_version)
        session = read_session_source(session_dir, run.report, date)
        with self._transaction() as db:
            session_row = _session_row(db, plot, session)
            provenance = run.report.get("provenance")
            run_id = _insert_run(db, session_row, run, "complete", "", provenance)
            plant_ids = _identify(db, _plot_id(db, plot), run_id, run.plants, max_distance_m)
            _insert_traits(db, run_id, run.plants, plant_ids)
            _insert_organs(db, run_id, run, plant_ids)
        log.info(
            "run %d: %s, %d plants of plot %s", run_id, session.session_id, len(run.plants), plot
        )
        return run_id

    def record_failure(
        self,
        plot: str,
        session_dir: Path,
        message: str,
        *,
        date: dt.date | None = None,
        settings: Mapping[str, Any] | None = None,
        software_version: str | None = None,
    ) -> int:
        """Record a reconstruction of a session that failed (no plants); returns the run id."""
        session = read_session_source(session_dir, {}, date)
        run = RunSource(Path(), [], {}, dict(settings or {}), software_version or "unknown")
        provenance = _failure_provenance(session_dir, settings)
        with self._transaction() as db:
            session_row = _session_row(db, plot, session)
            return _insert_run(db, session_row, run, "failed", message, provenance)

    def add_manual(
        self, plot: str, date: dt.date, records: list[ManualRecord], source: str = ""
    ) -> int:
        """Hand measurements of ``plot`` on ``date``; ``plant`` is the season plant number.
        Returns how many were stored (a second set for the same plant and date replaces it)."""
        with self._transaction() as db:
            plot_id = _plot_id(db, plot, create=False)
            for record in records:
                row = db.execute(
                    "SELECT id FROM plants WHERE plot_id = ? AND number = ?",
                    (plot_id, record.plant),
                ).fetchone()
                if row is None:
                    raise ResultsDBError(f"plot {plot} has no plant {record.plant}")
                db.execute(
                    "INSERT OR REPLACE INTO manual (plant_id, date, height_cm, width_cm, source) "
                    "VALUES (?, ?, ?, ?, ?)",
                    (row[0], date.isoformat(), record.height_cm, record.width_cm, source),
                )
        return len(records)

    # --- reading ------------------------------------------------------------------------

    def is_done(self, session_id: str, settings_sha256: str, software_version: str) -> bool:
        """Whether a complete run of the session with these settings and version is recorded."""
        row = self.connection.execute(
            "SELECT 1 FROM runs JOIN sessions ON sessions.id = runs.session_id "
            "WHERE sessions.session_id = ? AND runs.settings_sha256 = ? "
            "AND runs.software_version = ? AND runs.status = 'complete' LIMIT 1",
            (session_id, settings_sha256, software_version),
        ).fetchone()
        return row is not None

    def runs(self, plot: str | None = None) -> list[RunInfo]:
        """Recorded runs (of ``plot``, or all), by date then run id."""
        query = (
            "SELECT runs.id, plots.name, sessions.session_id, sessions.date, runs.status, "
            "runs.recorded, runs.results_dir, runs.software_version, runs.settings_sha256, "
            "(SELECT COUNT(*) FROM traits WHERE traits.run_id = runs.id), runs.message, "
            "runs.provenance FROM runs JOIN sessions ON sessions.id = runs.session_id "
            "JOIN plots ON plots.id = sessions.plot_id "
        )
        arguments: tuple[Any, ...] = ()
        if plot is not None:
            query, arguments = query + "WHERE plots.name = ? ", (plot,)
        rows = self.connection.execute(query + "ORDER BY sessions.date, runs.id", arguments)
        return [
            RunInfo(
                r[0],
                r[1],
                r[2],
                dt.date.fromisoformat(r[3]),
                r[4],
                r[5],
                r[6],
                r[7],
                r[8],
                r[9],
                r[10],
                _document(r[11]),
            )
            for r in rows
        ]

    def run_of_results_dir(self, results_dir: Path) -> RunInfo | None:
        """The latest run recorded from ``results_dir``, if any."""
        wanted = str(results_dir.resolve())
        matching = [r for r in self.runs() if r.results_dir == wanted]
        return matching[-1] if matching else None

    def session_calibration(self, session_id: str) -> dict[str, Any] | None:
        row = self.connection.execute(
            "SELECT calibrations.document FROM sessions JOIN calibrations "
            "ON calibrations.id = sessions.calibration_id WHERE sessions.session_id = ?",
            (session_id,),
        ).fetchone()
        return None if row is None else dict(json.loads(row[0]))

    def history(self, plot: str) -> list[Observation]:
        """Every plant's traits by date: per session, its latest complete run."""
        _plot_id(self.connection, plot, create=False)
        rows = self.connection.execute(
            "SELECT plants.id, plants.number, sessions.date, sessions.session_id, runs.id, "
            "traits.x_m, traits.y_m, traits.height_cm, traits.width_cm "
            + _LATEST_RUNS.format(table="traits")
            + "ORDER BY plants.number, sessions.date, sessions.session_id",
            (plot,),
        )
        return [Observation(r[0], r[1], dt.date.fromisoformat(r[2]), *r[3:]) for r in rows]

    def leaf_history(self, plot: str) -> list[LeafObservation]:
        """Every leaf's traits by date (per session, its latest complete run), by plant and
        leaf number: how a leaf grows."""
        _plot_id(self.connection, plot, create=False)
        rows = self.connection.execute(
            "SELECT plants.number, leaves.leaf_id, sessions.date, sessions.session_id, runs.id, "
            f"{', '.join('leaves.' + t for t in LEAF_TRAITS)} "
            + _LATEST_RUNS.format(table="leaves")
            + "ORDER BY plants.number, leaves.leaf_id, sessions.date, sessions.session_id",
            (plot,),
        )
        return [
            LeafObservation(
                r[0],
                r[1],
                dt.date.fromisoformat(r[2]),
                r[3],
                r[4],
                dict(zip(LEAF_TRAITS, r[5:], strict=True)),
            )
            for r in rows
        ]

    def organ_history(self, plot: str) -> list[tuple[int, dt.date, dict[str, Any]]]:
        """Per plant number and date: leaf count, leaf area and stem diameter (latest complete
        run of each session; ``None`` where not measured)."""
        _plot_id(self.connection, plot, create=False)
        rows = self.connection.execute(
            "SELECT plants.number, sessions.date, traits.leaf_count, traits.leaf_area_cm2, "
            "traits.stem_diameter_mm "
            + _LATEST_RUNS.format(table="traits")
            + "ORDER BY plants.number, sessions.date, sessions.session_id",
            (plot,),
        )
        return [
            (r[0], dt.date.fromisoformat(r[1]), dict(zip(PLANT_ORGAN_TRAITS, r[2:], strict=True)))
            for r in rows
        ]

    def manual(self, plot: str) -> list[tuple[int, dt.date, float | None, float | None]]:
        """Hand measurements of ``plot``: (plant number, date, height_cm, width_cm)."""
        rows = self.connection.execute(
            "SELECT plants.number, manual.date, manual.height_cm, manual.width_cm FROM manual "
            "JOIN plants ON plants.id = manual.plant_id JOIN plots ON plots.id = plants.plot_id "
            "WHERE plots.name = ? ORDER BY plants.number, manual.date",
            (plot,),
        )
        return [(r[0], dt.date.fromisoformat(r[1]), r[2], r[3]) for r in rows]


# --- the steps of a run's transaction -----------------------------------------------------


def _now() -> str:
    return dt.datetime.now().astimezone().isoformat(timespec="seconds")


def _plot_id(db: sqlite3.Connection, plot: str, create: bool = True) -> int:
    if not plot.strip():
        raise ResultsDBError("the plot name is empty")
    row = db.execute("SELECT id FROM plots WHERE name = ?", (plot,)).fetchone()
    if row is not None:
        return int(row[0])
    if not create:
        raise ResultsDBError(f"no plot named {plot!r} in the results database")
    return int(
        db.execute("INSERT INTO plots (name, created) VALUES (?, ?)", (plot, _now())).lastrowid or 0
    )


def _calibration_id(db: sqlite3.Connection, document: dict[str, Any] | None) -> int | None:
    if document is None:
        return None
    text = canonical_json(document)
    sha = settings_hash(document)
    db.execute("INSERT OR IGNORE INTO calibrations (sha256, document) VALUES (?, ?)", (sha, text))
    return int(db.execute("SELECT id FROM calibrations WHERE sha256 = ?", (sha,)).fetchone()[0])


def _session_row(db: sqlite3.Connection, plot: str, session: SessionSource) -> int:
    plot_id = _plot_id(db, plot)
    row = db.execute(
        "SELECT sessions.id, plots.name, sessions.date FROM sessions "
        "JOIN plots ON plots.id = sessions.plot_id WHERE session_id = ?",
        (session.session_id,),
    ).fetchone()
    if row is None:
        cursor = db.execute(
            "INSERT INTO sessions (session_id, plot_id, date, folder, calibration_id) "
            "VALUES (?, ?, ?, ?, ?)",
            (
                session.session_id,
                plot_id,
                session.date.isoformat(),
                None if session.folder is None else str(session.folder),
                _calibration_id(db, session.calibration),
            ),
        )
        return int(cursor.lastrowid or 0)
    if row[1] != plot:
        raise ResultsDBError(f"session {session.session_id} is recorded for plot {row[1]!r}")
    if row[2] != session.date.isoformat():
        raise ResultsDBError(f"session {session.session_id} is recorded on {row[2]}")
    return int(row[0])


def _document(text: str | None) -> dict[str, Any] | None:
    if text is None:
        return None
    document = json.loads(text)
    return document if isinstance(document, dict) else None


def _failure_provenance(
    session_dir: Path, settings: Mapping[str, Any] | None
) -> dict[str, Any] | None:
    """The provenance of a run that failed: of its session, when the session can be read."""
    from fieldapp.errors import FieldappError
    from fieldapp.io.session import load_session
    from fieldapp.provenance import provenance_of

    try:
        return provenance_of(load_session(session_dir, allow_empty=True), settings or {}).document
    except FieldappError as error:
        log.info("%s: no provenance for the failed run (%s)", session_dir, error)
        return None


def _provenance_columns(provenance: Any) -> tuple[str | None, ...]:
    """(document, source kind, calibration sha256, software commit) of a provenance document;
    all ``None`` when there is none."""
    if not isinstance(provenance, dict):
        return (None, None, None, None)
    parts = {k: provenance.get(k) or {} for k in ("source", "calibration", "software")}
    return (
        canonical_json(provenance),
        *(_text(parts[k].get(f)) for k, f in (("source", "kind"), ("calibration", "sha256"))),
        _text(parts["software"].get("commit")),
    )


def _text(value: Any) -> str | None:
    return None if value is None else str(value)


def _insert_run(
    db: sqlite3.Connection,
    session_row: int,
    run: RunSource,
    status: str,
    message: str,
    provenance: Any = None,
) -> int:
    cursor = db.execute(
        "INSERT INTO runs (session_id, recorded, results_dir, settings, settings_sha256, "
        "software_version, timings, status, message, report, provenance, source, "
        "calibration_sha256, software_commit) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
        (
            session_row,
            _now(),
            str(run.results_dir.resolve()) if status == "complete" else None,
            canonical_json(run.settings),
            settings_hash(run.settings),
            run.software_version,
            canonical_json(run.timings_s),
            status,
            message,
            canonical_json(run.report),
            *_provenance_columns(provenance),
        ),
    )
    return int(cursor.lastrowid or 0)


def _identify(
    db: sqlite3.Connection,
    plot_id: int,
    run_id: int,
    plants: list[PlantRecord],
    max_distance_m: float,
) -> list[tuple[int, float | None]]:
    """(season plant id, distance to where it was seen before) for each plant of the run."""
    known = db.execute(
        "SELECT plants.id, AVG(traits.x_m), AVG(traits.y_m) FROM plants "
        "JOIN traits ON traits.plant_id = plants.id WHERE plants.plot_id = ? "
        "GROUP BY plants.id ORDER BY plants.id",
        (plot_id,),
    ).fetchall()
    known_xy = np.array([[k[1], k[2]] for k in known], np.float64).reshape(-1, 2)
    observed_xy = np.array([[p.x_m, p.y_m] for p in plants], np.float64).reshape(-1, 2)
    matches = match_positions(known_xy, observed_xy, max_distance_m)
    number = db.execute(
        "SELECT COALESCE(MAX(number), 0) FROM plants WHERE plot_id = ?", (plot_id,)
    ).fetchone()[0]
    result: list[tuple[int, float | None]] = []
    for index, match in enumerate(matches):
        if match is not None:
            distance = float(np.linalg.norm(observed_xy[index] - known_xy[match]))
            result.append((int(known[match][0]), distance))
            continue
        number += 1
        cursor = db.execute(
            "INSERT INTO plants (plot_id, number, first_run_id) VALUES (?, ?, ?)",
            (plot_id, number, run_id),
        )
        result.append((int(cursor.lastrowid or 0), None))
    return result


def _insert_traits(
    db: sqlite3.Connection,
    run_id: int,
    plants: list[PlantRecord],
    plant_ids: list[tuple[int, float | None]],
) -> None:
    db.executemany(
        "INSERT INTO traits (run_id, plant_id, run_plant, x_m, y_m, height_cm, width_cm, points, "
        "match_distance_m) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
        [
            (run_id, pid, p.plant, p.x_m, p.y_m, p.height_cm, p.width_cm, p.points, distance)
            for p, (pid, distance) in zip(plants, plant_ids, strict=True)
        ],
    )


def _insert_organs(
    db: sqlite3.Connection,
    run_id: int,
    run: RunSource,
    plant_ids: list[tuple[int, float | None]],
) -> None:
    """The run's organ traits: plant-level columns of ``traits`` and one ``leaves`` row per
    leaf, under each plant's season id."""
    season = {p.plant: pid for p, (pid, _) in zip(run.plants, plant_ids, strict=True)}
    for plant, organs in run.organs.items():
        db.execute(
            "UPDATE traits SET leaf_count = ?, leaf_area_cm2 = ?, stem_diameter_mm = ? "
            "WHERE run_id = ? AND plant_id = ?",
            (*(organs.get(t) for t in PLANT_ORGAN_TRAITS), run_id, season[plant]),
        )
        db.executemany(
            f"INSERT INTO leaves (run_id, plant_id, leaf_id, {', '.join(LEAF_TRAITS)}) "
            f"VALUES (?, ?, ?, {', '.join('?' for _ in LEAF_TRAITS)})",
            [
                (run_id, season[plant], int(leaf["leaf_id"]), *(leaf.get(t) for t in LEAF_TRAITS))
                for leaf in organs["leaves"]
            ],
        )
