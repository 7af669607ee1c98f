"""Writing the chosen formats of an export into one folder, each file durably."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

from fieldapp.errors import FieldappError
from fieldapp.export import brapi, isatab, tables
from fieldapp.export.clouds import labelled_cloud, ply_with_fields, write_laz
from fieldapp.export.data import ExportData
from fieldapp.io.durable import write_bytes_durably

FORMATS = ("csv", "laz", "ply", "isa", "brapi")


def parse_formats(text: str) -> list[str]:
    chosen = [f.strip().lower() for f in text.split(",") if f.strip()]
    unknown = [f for f in chosen if f not in FORMATS]
    if unknown or not chosen:
        raise FieldappError(
            f"--formats {text!r}: choose among {', '.join(FORMATS)} (comma-separated)"
        )
    return chosen


def _text(path: Path, text: str) -> Path:
    write_bytes_durably(path, text.encode("utf-8"))
    return path


def _json(path: Path, document: object) -> Path:
    return _text(path, json.dumps(document, indent=1, ensure_ascii=False) + "\n")


def export(data: ExportData, out: Path, formats: list[str], today: dt.date) -> list[Path]:
    """Write ``formats`` of ``data`` into ``out``; returns the files written."""
    if not data.observations:
        raise FieldappError("nothing to export: no plant was measured")
    written: list[Path] = []
    if "csv" in formats:
        written.append(_text(out / "plants.csv", tables.plants_csv(data)))
        written.append(_text(out / "observations.csv", tables.observations_csv(data)))
        if data.leaves:
            written.append(_text(out / "leaves.csv", tables.leaves_csv(data)))
    if "isa" in formats:
        for name, text in isatab.bundle(data, today).items():
            written.append(_text(out / "isa" / name, text))
    if "brapi" in formats:
        written.append(
            _json(out / "brapi" / "observationunits.json", brapi.observation_units(data))
        )
        written.append(_json(out / "brapi" / "observations.json", brapi.observations(data)))
        written.append(
            _json(out / "brapi" / "observationvariables.json", brapi.observation_variables(data))
        )
    if {"laz", "ply"} & set(formats):
        written += _clouds(data, out, formats)
    return written


def _clouds(data: ExportData, out: Path, formats: list[str]) -> list[Path]:
    written = []
    for results in data.results_dirs[-1:]:  # the latest date's cloud
        cloud = labelled_cloud(results)
        if "laz" in formats:
            write_laz(out / "cloud.laz", cloud)
            written.append(out / "cloud.laz")
        if "ply" in formats:
            written.append(out / "cloud.ply")
            write_bytes_durably(written[-1], ply_with_fields(cloud))
    return written
