"""What is exported: the plants of one or more dates, each with its traits, and the clouds.

From results folders (``plants.csv``, ``leaves.csv`` where organs were measured, ``plants/``,
``cloud.ply`` of ``fieldapp reconstruct`` or ``fieldapp import cloud``), one date each; or from
the results database, every date of a plot with plant ids that hold all season (plants only:
the database keeps no leaves).
"""

from __future__ import annotations

import csv
import datetime as dt
import math
from dataclasses import dataclass, field
from pathlib import Path

from fieldapp.errors import FieldappError
from fieldapp.export.variables import Variable, variable_of


@dataclass(frozen=True)
class PlantObservation:
    """One plant on one date: its position (field frame, m), grid cell when known, traits."""

    plant_id: int
    date: dt.date
    x_m: float
    y_m: float
    row: int | None
    column: int | None
    values: dict[str, float]
    """plants.csv column -> value, for the columns that are variables."""


@dataclass(frozen=True)
class LeafObservation:
    """One leaf of a plant on one date: ``leaf_id`` from the bottom, as in ``leaves.csv``, and
    its traits (``leaves.csv`` column -> value; NaN where blank)."""

    plant_id: int
    date: dt.date
    leaf_id: int
    values: dict[str, float]


@dataclass
class ExportData:
    study: str
    observations: list[PlantObservation]
    variables: list[Variable]
    results_dirs: list[Path] = field(default_factory=list)
    """Results folders whose clouds are exported (the latest date's)."""
    notes: list[str] = field(default_factory=list)
    leaves: list[LeafObservation] = field(default_factory=list)
    """Every leaf of every date whose results folder has ``leaves.csv``."""

    @property
    def dates(self) -> list[dt.date]:
        return sorted({o.date for o in self.observations})

    @property
    def plant_ids(self) -> list[int]:
        return sorted({o.plant_id for o in self.observations})


def _number(text: str, path: Path, line: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise FieldappError(f"{path}: line {line}, {column}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise FieldappError(f"{path}: line {line}, {column}: {text!r} is not finite")
    return value


def read_plants_csv(path: Path, date: dt.date) -> tuple[list[PlantObservation], list[Variable]]:
    """The rows of a results folder's ``plants.csv``; raises naming the file and field."""
    if not path.is_file():
        raise FieldappError(f"{path}: file is missing (is this a results folder?)")
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        header = reader.fieldnames or []
        missing = [c for c in ("plant", "x_m", "y_m") if c not in header]
        if missing:
            raise FieldappError(f"{path}: columns {', '.join(missing)} are missing")
        variables = [v for c in header if (v := variable_of(c)) is not None]
        observations = []
        for line, row in enumerate(reader, start=2):
            values = {
                v.column: _number(row[v.column], path, line, v.column)
                if (row[v.column] or "").strip()
                else math.nan  # a trait not measured on this plant (a blank cell)
                for v in variables
            }
            observations.append(
                PlantObservation(
                    int(_number(row["plant"], path, line, "plant")),
                    date,
                    _number(row["x_m"], path, line, "x_m"),
                    _number(row["y_m"], path, line, "y_m"),
                    _grid(row, ROW_COLUMNS, path, line),
                    _grid(row, COLUMN_COLUMNS, path, line),
                    values,
                )
            )
    return observations, variables


ROW_COLUMNS = ("row", "grid_row")
COLUMN_COLUMNS = ("column", "col", "grid_column", "grid_col")
"""Names of the planting grid's row and column in plants.csv, first found wins."""


def _grid(row: dict[str, str], names: tuple[str, ...], path: Path, line: int) -> int | None:
    for name in names:
        text = (row.get(name) or "").strip()
        if text:
            return int(_number(text, path, line, name))
    return None


def read_leaves_csv(path: Path, date: dt.date) -> list[LeafObservation]:
    """The leaves of a results folder's ``leaves.csv`` (none when the folder has no such file:
    organs not measured); raises naming the file, row and column of a bad cell."""
    if not path.is_file():
        return []
    from fieldapp.results.organ_tables import LEAF_TRAITS, read_table

    leaves = []
    for row in read_table(path, ("plant_id", "leaf_id")):
        if row["plant_id"] is None or row["leaf_id"] is None:
            raise FieldappError(f"{path}: a row without plant_id or leaf_id: {row}")
        values = {c: math.nan if row.get(c) is None else float(row[c]) for c in LEAF_TRAITS}
        leaves.append(LeafObservation(int(row["plant_id"]), date, int(row["leaf_id"]), values))
    return leaves


def from_results_dirs(folders: list[Path], dates: list[dt.date], study: str) -> ExportData:
    """One date per folder (``dates`` in the same order)."""
    observations: list[PlantObservation] = []
    variables: dict[str, Variable] = {}
    leaves: list[LeafObservation] = []
    for folder, date in zip(folders, dates, strict=True):
        rows, found = read_plants_csv(folder / "plants.csv", date)
        observations += rows
        variables.update({v.column: v for v in found})
        leaves += read_leaves_csv(folder / "leaves.csv", date)
    measured = [  # a column blank on every plant and date (not measured) is no variable
        v
        for v in variables.values()
        if any(v.column in o.values and not math.isnan(o.values[v.column]) for o in observations)
    ]
    for o in observations:  # a folder without a column that another has: not measured there
        for v in measured:
            o.values.setdefault(v.column, math.nan)
    data = ExportData(study, observations, measured, list(folders), leaves=leaves)
    if len(folders) > 1:
        data.notes.append(
            "plant ids are those of each results folder; for ids that hold all season record "
            "the runs in the results database and export with --db and --plot"
        )
    return data


def from_database(db_path: Path, plot: str) -> ExportData:
    """Every date of ``plot`` in the results database: plant ids that hold all season."""
    from fieldapp.export.variables import KNOWN
    from fieldapp.results.db import ResultsDB

    with ResultsDB.open(db_path, create=False) as db:
        history = db.history(plot)
        runs = [r for r in db.runs(plot) if r.status == "complete" and r.results_dir]
    if not history:
        raise FieldappError(f"{db_path}: plot {plot!r} has no measured plant")
    observations = [
        PlantObservation(
            o.plant_number,
            o.date,
            o.x_m,
            o.y_m,
            None,
            None,
            {"height_cm": o.height_cm, "width_cm": o.width_cm},
        )
        for o in history
    ]
    variables = [KNOWN["height_cm"], KNOWN["width_cm"]]
    latest = [Path(runs[-1].results_dir)] if runs and runs[-1].results_dir else []
    data = ExportData(plot, observations, variables, latest)
    data.notes.append("clouds of the latest run only (the ids in them are that run's)")
    return data
