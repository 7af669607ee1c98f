"""Reading a reconstruction's output folder (``plants.csv``, ``report.json``) and
``manual.csv`` hand measurements, with every bad cell named by file, row and column.

Row numbers are the line numbers a spreadsheet shows (the header is row 1).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from fieldapp.errors import FormatError, Problem
from fieldapp.io.jsonfile import read_json

PLANTS_COLUMNS = ("plant", "x_m", "y_m", "height_cm", "width_cm", "points")
MANUAL_COLUMNS = ("plant", "height_cm", "width_cm")

T = TypeVar("T")


@dataclass(frozen=True)
class PlantRecord:
    """One row of ``plants.csv``: the plant's base in the field frame and its traits."""

    plant: int
    x_m: float
    y_m: float
    height_cm: float
    width_cm: float
    points: int


@dataclass(frozen=True)
class ManualRecord:
    """One row of ``manual.csv``; ``None`` where the cell is empty (not measured)."""

    plant: int
    height_cm: float | None
    width_cm: float | None


def _rows(path: Path, columns: tuple[str, ...]) -> Iterator[tuple[int, dict[str, str]]]:
    """(row number, cells) of a CSV file whose header holds ``columns`` (others ignored)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FormatError([Problem(str(path), "", "file is missing")]) from None
    except UnicodeDecodeError:
        raise FormatError([Problem(str(path), "", "not UTF-8 text")]) from None
    except OSError as error:
        raise FormatError([Problem(str(path), "", f"cannot read: {error.strerror}")]) from None
    reader = csv.DictReader(text.splitlines())
    header = [name.strip() for name in reader.fieldnames or []]
    missing = [c for c in columns if c not in header]
    if missing:
        raise FormatError([Problem(str(path), "header", f"missing column(s) {', '.join(missing)}")])
    reader.fieldnames = header
    for row in reader:
        if not any((v or "").strip() for k, v in row.items() if k is not None):
            continue
        yield reader.line_num, {c: (row.get(c) or "").strip() for c in columns}


def _cell(
    path: Path, row: int, column: str, text: str, parse: Callable[[str], T], problems: list[Problem]
) -> T | None:
    try:
        return parse(text)
    except ValueError as error:
        problems.append(Problem(str(path), f"row {row} column {column}", str(error)))
        return None


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a whole number") from None


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{text!r} is not a finite number")
    return value


def _length(text: str) -> float:
    value = _number(text)
    if value < 0.0:
        raise ValueError(f"{text!r} is negative")
    return value


def _optional_length(text: str) -> float | None:
    return None if text == "" else _length(text)


def _duplicates(path: Path, ids: list[tuple[int, int]], problems: list[Problem]) -> None:
    first: dict[int, int] = {}
    for row, plant in ids:
        if plant in first:
            problems.append(
                Problem(
                    str(path),
                    f"row {row} column plant",
                    f"plant {plant} is already on row {first[plant]}",
                )
            )
        first.setdefault(plant, row)


def read_plants_csv(path: Path) -> list[PlantRecord]:
    """The rows of a reconstruction's ``plants.csv``; raises :class:`FormatError`."""
    records: list[PlantRecord] = []
    problems: list[Problem] = []
    ids: list[tuple[int, int]] = []
    parsers: dict[str, Callable[[str], Any]] = {
        "plant": _integer,
        "x_m": _number,
        "y_m": _number,
        "height_cm": _length,
        "width_cm": _length,
        "points": _integer,
    }
    for row, cells in _rows(path, PLANTS_COLUMNS):
        values: dict[str, Any] = {
            c: _cell(path, row, c, cells[c], parsers[c], problems) for c in PLANTS_COLUMNS
        }
        if all(v is not None for v in values.values()):
            records.append(PlantRecord(**values))
            ids.append((row, int(values["plant"])))
    _duplicates(path, ids, problems)
    if problems:
        raise FormatError(problems)
    return records


def read_manual_csv(path: Path) -> list[ManualRecord]:
    """Hand measurements ``plant,height_cm,width_cm`` (an empty cell: not measured)."""
    records: list[ManualRecord] = []
    problems: list[Problem] = []
    ids: list[tuple[int, int]] = []
    for row, cells in _rows(path, MANUAL_COLUMNS):
        plant = _cell(path, row, "plant", cells["plant"], _integer, problems)
        height = _cell(path, row, "height_cm", cells["height_cm"], _optional_length, problems)
        width = _cell(path, row, "width_cm", cells["width_cm"], _optional_length, problems)
        if plant is not None:
            ids.append((row, plant))
            records.append(ManualRecord(plant, height, width))
    _duplicates(path, ids, problems)
    if not records and not problems:
        problems.append(Problem(str(path), "", "no measurements"))
    if problems:
        raise FormatError(problems)
    return records


def read_report(path: Path) -> dict[str, Any]:
    """A reconstruction's ``report.json`` (a JSON object); raises :class:`FormatError`."""
    document = read_json(path)
    if not isinstance(document, dict):
        raise FormatError([Problem(str(path), "(document)", "must be a JSON object")])
    return document
