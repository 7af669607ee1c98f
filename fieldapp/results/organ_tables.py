"""Organ tables of a reconstruction's folder: ``leaves.csv`` and the organ columns of
``plants.csv`` (both optional: older runs have none), read as numbers with every bad cell named
by file, row and column."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from fieldapp.errors import FormatError, Problem

LEAF_TRAITS = (
    "length_cm",
    "max_width_cm",
    "area_cm2",
    "angle_from_stem_deg",
    "azimuth_deg",
    "insertion_height_cm",
)
PLANT_ORGAN_TRAITS = ("leaf_count", "leaf_area_cm2", "stem_diameter_mm")

INTEGER_COLUMNS = ("plant", "plant_id", "leaf_id", "leaf_count", "points")


def read_table(path: Path, required: tuple[str, ...]) -> list[dict[str, Any]]:
    """Rows of a CSV file as numbers (``None`` for empty cells); every bad cell is named by
    file, row and column."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FormatError([Problem(str(path), "", "file is missing")]) from None
    except (OSError, UnicodeDecodeError) as error:
        raise FormatError([Problem(str(path), "", f"cannot read: {error}")]) from None
    reader = csv.DictReader(text.splitlines())
    header = [name.strip() for name in reader.fieldnames or []]
    missing = [c for c in required if c not in header]
    if missing:
        raise FormatError([Problem(str(path), "header", f"missing column(s) {', '.join(missing)}")])
    reader.fieldnames = header
    rows: list[dict[str, Any]] = []
    problems: list[Problem] = []
    for row in reader:
        values: dict[str, Any] = {}
        for column, cell in row.items():
            if column is None:
                continue
            values[column] = _number(path, reader.line_num, column, (cell or "").strip(), problems)
        if any(v is not None for v in values.values()):
            rows.append(values)
    if problems:
        raise FormatError(problems)
    return rows


def _number(path: Path, row: int, column: str, text: str, problems: list[Problem]) -> Any:
    if text == "":
        return None
    try:
        value = float(text)
    except ValueError:
        problems.append(
            Problem(str(path), f"row {row} column {column}", f"{text!r} is not a number")
        )
        return None
    if not math.isfinite(value):
        problems.append(Problem(str(path), f"row {row} column {column}", "not a finite number"))
        return None
    if column in INTEGER_COLUMNS:
        if not value.is_integer():
            problems.append(
                Problem(str(path), f"row {row} column {column}", f"{text!r} is not a whole number")
            )
            return None
        return int(value)
    return value
