"""The results database's schema: ordered migrations, the version in ``PRAGMA user_version``.

Migration ``i`` (1-based) takes a database from version ``i - 1`` to ``i``; each runs in its
own transaction together with the version bump, so a crash leaves the old or the new version.
Append migrations; never edit one that has shipped.
"""

from __future__ import annotations

import logging
import sqlite3
from pathlib import Path

from fieldapp.errors import FieldappError

log = logging.getLogger(__name__)

BUSY_TIMEOUT_MS = 10_000

MIGRATIONS: tuple[tuple[str, ...], ...] = (
    (
        """CREATE TABLE plots (
            id INTEGER PRIMARY KEY,
            name TEXT NOT NULL UNIQUE,
            created TEXT NOT NULL)""",
        """CREATE TABLE calibrations (
            id INTEGER PRIMARY KEY,
            sha256 TEXT NOT NULL UNIQUE,
            document TEXT NOT NULL)""",
        """CREATE TABLE sessions (
            id INTEGER PRIMARY KEY,
            session_id TEXT NOT NULL UNIQUE,
            plot_id INTEGER NOT NULL REFERENCES plots(id),
            date TEXT NOT NULL,
            folder TEXT,
            calibration_id INTEGER REFERENCES calibrations(id))""",
        """CREATE TABLE runs (
            id INTEGER PRIMARY KEY,
            session_id INTEGER NOT NULL REFERENCES sessions(id),
            recorded TEXT NOT NULL,
            results_dir TEXT,
            settings TEXT NOT NULL,
            settings_sha256 TEXT NOT NULL,
            software_version TEXT NOT NULL,
            timings TEXT NOT NULL,
            status TEXT NOT NULL CHECK (status IN ('complete', 'failed')),
            message TEXT NOT NULL DEFAULT '',
            report TEXT NOT NULL DEFAULT '{}')""",
        """CREATE TABLE plants (
            id INTEGER PRIMARY KEY,
            plot_id INTEGER NOT NULL REFERENCES plots(id),
            number INTEGER NOT NULL,
            first_run_id INTEGER NOT NULL REFERENCES runs(id),
            UNIQUE (plot_id, number))""",
        """CREATE TABLE traits (
            run_id INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,
            plant_id INTEGER NOT NULL REFERENCES plants(id),
            run_plant INTEGER NOT NULL,
            x_m REAL NOT NULL,
            y_m REAL NOT NULL,
            height_cm REAL NOT NULL,
            width_cm REAL NOT NULL,
            points INTEGER NOT NULL,
            match_distance_m REAL,
            PRIMARY KEY (run_id, plant_id),
            UNIQUE (run_id, run_plant))""",
        """CREATE TABLE manual (
            id INTEGER PRIMARY KEY,
            plant_id INTEGER NOT NULL REFERENCES plants(id),
            date TEXT NOT NULL,
            height_cm REAL,
            width_cm REAL,
            source TEXT NOT NULL DEFAULT '',
            UNIQUE (plant_id, date))""",
    ),
    (
        "CREATE INDEX runs_by_session ON runs(session_id, status)",
        "CREATE INDEX runs_by_key ON runs(settings_sha256, software_version)",
        "CREATE INDEX traits_by_plant ON traits(plant_id)",
        "CREATE INDEX sessions_by_plot ON sessions(plot_id, date)",
    ),
    (
        "ALTER TABLE traits ADD COLUMN leaf_count INTEGER",
        "ALTER TABLE traits ADD COLUMN leaf_area_cm2 REAL",
        "ALTER TABLE traits ADD COLUMN stem_diameter_mm REAL",
        """CREATE TABLE leaves (
            run_id INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,
            plant_id INTEGER NOT NULL REFERENCES plants(id),
            leaf_id INTEGER NOT NULL,
            length_cm REAL,
            max_width_cm REAL,
            area_cm2 REAL,
            angle_from_stem_deg REAL,
            azimuth_deg REAL,
            insertion_height_cm REAL,
            PRIMARY KEY (run_id, plant_id, leaf_id))""",
        "CREATE INDEX leaves_by_plant ON leaves(plant_id, leaf_id)",
    ),
    (
        # Where each run came from (fieldapp.provenance): the whole document, and its most
        # asked parts as columns. Runs recorded before have NULL: their provenance is unknown.
        "ALTER TABLE runs ADD COLUMN provenance TEXT",
        "ALTER TABLE runs ADD COLUMN source TEXT",
        "ALTER TABLE runs ADD COLUMN calibration_sha256 TEXT",
        "ALTER TABLE runs ADD COLUMN software_commit TEXT",
    ),
    (  # manual corrections (fieldapp/results/corrections.py): the traits rows they changed,
        # and each session's corrections.json, kept for a re-run into another folder
        "ALTER TABLE traits ADD COLUMN corrected INTEGER NOT NULL DEFAULT 0",
        """CREATE TABLE corrections (
            session_id TEXT PRIMARY KEY,
            results_dir TEXT NOT NULL,
            document TEXT NOT NULL,
            saved TEXT NOT NULL)""",
    ),
)

SCHEMA_VERSION = len(MIGRATIONS)


class ResultsDBError(FieldappError):
    """The results database cannot be used (not a database, too new, locked...)."""


def connect(path: Path) -> sqlite3.Connection:
    """A connection in autocommit mode (transactions are explicit) with WAL, synchronous=FULL
    and foreign keys on."""
    try:
        connection = sqlite3.connect(path, isolation_level=None, timeout=BUSY_TIMEOUT_MS / 1000)
    except sqlite3.DatabaseError as error:
        raise ResultsDBError(f"{path}: not a usable results database ({error})") from None
    try:
        connection.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        mode = connection.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        connection.execute("PRAGMA synchronous = FULL")
        connection.execute("PRAGMA foreign_keys = ON")
    except sqlite3.DatabaseError as error:
        connection.close()  # not left to the collector: it holds the file (3.13 warns)
        raise ResultsDBError(f"{path}: not a usable results database ({error})") from None
    if mode != "wal":
        log.warning("%s: journal mode %s (WAL unavailable on this file system)", path, mode)
    return connection


def schema_version(connection: sqlite3.Connection) -> int:
    return int(connection.execute("PRAGMA user_version").fetchone()[0])


def migrate(connection: sqlite3.Connection, path: Path, target: int = SCHEMA_VERSION) -> int:
    """Apply the pending migrations in order up to ``target``; returns the version reached."""
    try:
        version = schema_version(connection)
    except sqlite3.DatabaseError as error:
        raise ResultsDBError(f"{path}: not a usable results database ({error})") from None
    if version > SCHEMA_VERSION:
        raise ResultsDBError(
            f"{path}: schema version {version} is newer than this fieldapp knows "
            f"({SCHEMA_VERSION}); update fieldapp"
        )
    while version < target:
        connection.execute("BEGIN IMMEDIATE")
        try:
            version = schema_version(connection)  # another process may have migrated meanwhile
            if version < target:
                for statement in MIGRATIONS[version]:
                    connection.execute(statement)
                version += 1
                connection.execute(f"PRAGMA user_version = {version}")
            connection.execute("COMMIT")
        except BaseException:
            connection.execute("ROLLBACK")
            raise
        log.info("%s: schema at version %d", path, version)
    return version
