"""``fieldapp export``: results in standard formats (LAZ, PLY, ISA-Tab, BrAPI, CSV)."""

from __future__ import annotations

import argparse
import datetime as dt
from pathlib import Path
from typing import Any

from fieldapp.errors import FieldappError


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "export",
        help="export results: LAZ/PLY clouds with plant ids, MIAPPE ISA-Tab, BrAPI, CSV",
        description="Export results folders (of `fieldapp reconstruct` or `fieldapp import "
        "cloud`, one date each) or a plot of the results database (every date, plant ids "
        "that hold all season) into standard formats: cloud.laz (LAS 1.4, plant_id and organ "
        "dimensions), cloud.ply (scalar fields), isa/ (MIAPPE ISA-Tab), brapi/ (BrAPI v2 "
        "JSON), plants.csv and observations.csv (units in the headers).",
    )
    parser.add_argument("results", nargs="*", type=Path, help="results folders")
    parser.add_argument("--out", type=Path, required=True, help="the export folder")
    parser.add_argument(
        "--date",
        action="append",
        help="the date of each results folder (YYYY-MM-DD, once per folder, in order); "
        "default: from the results database, else the day the results were written",
    )
    parser.add_argument("--plot", help="export this plot of the results database instead")
    parser.add_argument("--db", type=Path, help="the results database (default: the settings')")
    parser.add_argument("--study", help="the study's name (default: the plot or first folder)")
    parser.add_argument(
        "--formats", default="csv,laz,ply,isa,brapi", help="any of csv,laz,ply,isa,brapi (all)"
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fieldapp.cli.results import database_path
    from fieldapp.export.data import from_database, from_results_dirs
    from fieldapp.export.write import export, parse_formats

    formats = parse_formats(args.formats)
    if bool(args.results) == bool(args.plot):
        raise FieldappError("give results folders, or --plot (with --db), one of the two")
    if args.plot:
        data = from_database(database_path(args), args.plot)
    else:
        dates, said = _dates(args)
        for line in said:
            print(line)
        data = from_results_dirs(args.results, dates, args.study or args.results[0].resolve().name)
    if args.study:
        data.study = args.study
    written = export(data, args.out, formats, dt.date.today())
    for note in data.notes:
        print(f"note: {note}")
    leaves = f", {len(data.leaves)} leaves" if data.leaves else ""
    print(
        f"{len(data.plant_ids)} plants{leaves}, {len(data.dates)} date(s), "
        f"{len(data.variables)} variables -> {len(written)} files in {args.out}"
    )
    return 0


def _dates(args: argparse.Namespace) -> tuple[list[dt.date], list[str]]:
    """Each folder's date: given, from the results database, or the day it was written."""
    from fieldapp.cli.results import parse_date

    if args.date:
        if len(args.date) != len(args.results):
            raise FieldappError(
                f"--date given {len(args.date)} times for {len(args.results)} results folders"
            )
        return [d for d in map(parse_date, args.date) if d is not None], []
    known = _dates_in_database(args)
    dates, said = [], []
    for folder in args.results:
        if folder in known:
            dates.append(known[folder])
            continue
        report = folder / "report.json"
        if not report.is_file():
            raise FieldappError(f"{report}: file is missing (is this a results folder?)")
        day = dt.date.fromtimestamp(report.stat().st_mtime)
        dates.append(day)
        said.append(f"{folder}: date {day} (the day the results were written; give --date)")
    return dates, said


def _dates_in_database(args: argparse.Namespace) -> dict[Path, dt.date]:
    from fieldapp.cli.results import database_path
    from fieldapp.results.db import ResultsDB

    path = database_path(args)
    if not path.is_file():
        return {}
    with ResultsDB.open(path, create=False) as db:
        runs = {r.results_dir: r.date for r in db.runs() if r.results_dir}
    return {f: runs[str(f.resolve())] for f in args.results if str(f.resolve()) in runs}
