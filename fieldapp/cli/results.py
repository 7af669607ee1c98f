"""``fieldapp results add|list|manual``: the season's results database."""

from __future__ import annotations

import argparse
import datetime as dt
from pathlib import Path
from typing import Any

from fieldapp.errors import FieldappError


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "results",
        help="record reconstructions in the results database and list them",
        description="The results database (default: settings.paths.results_db).",
    )
    parser.add_argument("--db", type=Path, help="the database file (default: from the settings)")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    add = verbs.add_parser("add", help="record a reconstruction's outputs")
    add.add_argument("results", type=Path, help="the reconstruction's output folder")
    add.add_argument("--plot", required=True, help="the plot's name")
    add.add_argument("--session", type=Path, help="the session folder (id, date, calibration)")
    add.add_argument("--date", help="the session's date, YYYY-MM-DD (default: the session's)")
    add.add_argument(
        "--max-distance-m", type=float, default=0.15, help="same plant within this (0.15 m)"
    )
    add.set_defaults(handler=run_add)
    listing = verbs.add_parser("list", help="list the recorded runs")
    listing.add_argument("--plot", help="only this plot")
    listing.set_defaults(handler=run_list)
    manual = verbs.add_parser("manual", help="store hand measurements (season plant numbers)")
    manual.add_argument("csv", type=Path, help="manual.csv: plant,height_cm,width_cm")
    manual.add_argument("--plot", required=True, help="the plot's name")
    manual.add_argument("--date", required=True, help="the date measured, YYYY-MM-DD")
    manual.set_defaults(handler=run_manual)


def parse_date(text: str | None) -> dt.date | None:
    if text is None:
        return None
    try:
        return dt.date.fromisoformat(text)
    except ValueError:
        raise FieldappError(f"--date: {text!r} is not a date (YYYY-MM-DD)") from None


def database_path(args: argparse.Namespace) -> Path:
    if args.db is not None:
        return Path(args.db)
    from fieldapp.settings import load_settings

    return load_settings().paths.results_db


def run_add(args: argparse.Namespace) -> int:
    from fieldapp.results.db import ResultsDB

    if args.max_distance_m <= 0:
        raise FieldappError("--max-distance-m must be positive")
    date = parse_date(args.date)
    with ResultsDB.open(database_path(args)) as db:
        run_id = db.record_run(
            args.plot,
            args.session,
            args.results,
            date=date,
            max_distance_m=args.max_distance_m,
        )
        run = next(r for r in db.runs(args.plot) if r.run_id == run_id)
    print(f"run {run_id}: {run.session_id} ({run.date}) of plot {run.plot}, {run.plants} plants")
    return 0


def run_list(args: argparse.Namespace) -> int:
    from fieldapp.results.db import ResultsDB

    with ResultsDB.open(database_path(args), create=False) as db:
        runs = db.runs(args.plot)
    print("run  plot  date  session  status  plants  version")
    for r in runs:
        print(
            f"{r.run_id}  {r.plot}  {r.date}  {r.session_id}  {r.status}  {r.plants}  "
            f"{r.software_version}"
        )
    return 0


def run_manual(args: argparse.Namespace) -> int:
    from fieldapp.results.db import ResultsDB
    from fieldapp.results.files import read_manual_csv

    date = parse_date(args.date)
    if date is None:
        raise FieldappError("--date is required")
    records = read_manual_csv(args.csv)
    with ResultsDB.open(database_path(args), create=False) as db:
        count = db.add_manual(args.plot, date, records, source=str(args.csv))
    print(f"{count} hand measurements of plot {args.plot} on {date}")
    return 0
