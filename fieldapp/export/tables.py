"""CSVs with units in their headers: one row per plant and date (wide), one row per
observation (long, with unit and method), one row per leaf and date."""

from __future__ import annotations

import csv
import io

from fieldapp.export.data import ExportData
from fieldapp.results.organ_tables import LEAF_TRAITS


def _format(value: float) -> str:
    return f"{value:.4f}".rstrip("0").rstrip(".") if value == value else ""


def plants_csv(data: ExportData) -> str:
    """``plant_id,date,x_m,y_m,row,column,<variable columns>``: names carry their units."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    columns = [v.column for v in data.variables]
    writer.writerow(["plant_id", "date", "x_m", "y_m", "row", "column", *columns])
    for o in sorted(data.observations, key=lambda o: (o.date, o.plant_id)):
        writer.writerow(
            [
                o.plant_id,
                o.date.isoformat(),
                _format(o.x_m),
                _format(o.y_m),
                "" if o.row is None else o.row,
                "" if o.column is None else o.column,
                *(_format(o.values[c]) for c in columns),
            ]
        )
    return buffer.getvalue()


def observations_csv(data: ExportData) -> str:
    """``plant_id,date,variable,value,unit,trait,method``: one observation per line."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["plant_id", "date", "variable", "value", "unit", "trait", "method"])
    for o in sorted(data.observations, key=lambda o: (o.date, o.plant_id)):
        for v in data.variables:
            if o.values[v.column] != o.values[v.column]:
                continue  # not measured on this plant (NaN): no observation
            value = _format(o.values[v.column])
            writer.writerow(
                [o.plant_id, o.date.isoformat(), v.name, value, v.unit, v.trait, v.method]
            )
    return buffer.getvalue()


def leaves_csv(data: ExportData) -> str:
    """``plant_id,date,leaf_id,length_cm,...``: every leaf of every date, ``leaves.csv``'s
    columns (units in their names) with the date after the plant."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["plant_id", "date", "leaf_id", *LEAF_TRAITS])
    for leaf in sorted(data.leaves, key=lambda o: (o.date, o.plant_id, o.leaf_id)):
        writer.writerow(
            [
                leaf.plant_id,
                leaf.date.isoformat(),
                leaf.leaf_id,
                *(_format(leaf.values[c]) for c in LEAF_TRAITS),
            ]
        )
    return buffer.getvalue()
