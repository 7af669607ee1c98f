"""A plot's season: each plant's traits by date, as a table, a CSV and growth series."""

from __future__ import annotations

import csv
import datetime as dt
import io

from fieldapp.results.db import Observation


def history_csv(observations: list[Observation]) -> str:
    """``plant,date,session,run,x_m,y_m,height_cm,width_cm``: one row per plant and date."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["plant", "date", "session", "run", "x_m", "y_m", "height_cm", "width_cm"])
    for o in observations:
        writer.writerow(
            [
                o.plant_number,
                o.date.isoformat(),
                o.session_id,
                o.run_id,
                f"{o.x_m:.4f}",
                f"{o.y_m:.4f}",
                f"{o.height_cm:.2f}",
                f"{o.width_cm:.2f}",
            ]
        )
    return buffer.getvalue()


def growth_series(
    observations: list[Observation], trait: str
) -> dict[int, list[tuple[dt.date, float]]]:
    """Per plant number, (date, value of ``trait`` in cm) in date order."""
    if trait not in ("height", "width"):
        raise ValueError(f"unknown trait {trait!r}")
    series: dict[int, list[tuple[dt.date, float]]] = {}
    for o in sorted(observations, key=lambda o: (o.plant_number, o.date, o.session_id)):
        series.setdefault(o.plant_number, []).append((o.date, getattr(o, f"{trait}_cm")))
    return series


def history_table(
    observations: list[Observation],
) -> tuple[list[dt.date], dict[int, dict[dt.date, Observation]]]:
    """The dates of the season and, per plant number, its observation on each date."""
    dates = sorted({o.date for o in observations})
    table: dict[int, dict[dt.date, Observation]] = {}
    for o in observations:
        table.setdefault(o.plant_number, {})[o.date] = o
    return dates, table
