"""``fieldapp history PLOT``: each plant's height and width by date, growth curves, CSV."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "history",
        help="a plot's plants through the season: table, growth curves (PNG), CSV",
        description="Each plant (one id all season) with its height and width on each date "
        "(the latest complete run of each session).",
    )
    parser.add_argument("plot", help="the plot's name")
    parser.add_argument("--db", type=Path, help="the database file (default: from the settings)")
    parser.add_argument("--csv", type=Path, help="write the history as CSV here")
    parser.add_argument("--figures", type=Path, help="write growth_height.png, growth_width.png")
    parser.set_defaults(handler=run)


def _cell(observation: Any) -> str:
    if observation is None:
        return "-"
    return f"{observation.height_cm:.1f}/{observation.width_cm:.1f}"


def run(args: argparse.Namespace) -> int:
    from fieldapp.cli.results import database_path
    from fieldapp.evaluate.figures import growth_png
    from fieldapp.io.durable import write_bytes_durably
    from fieldapp.results.db import ResultsDB
    from fieldapp.results.history import growth_series, history_csv, history_table

    with ResultsDB.open(database_path(args), create=False) as db:
        observations = db.history(args.plot)
    dates, table = history_table(observations)
    print(f"plot {args.plot}: {len(table)} plants on {len(dates)} dates (height/width cm)")
    print("plant  " + "  ".join(d.isoformat() for d in dates))
    for plant, by_date in sorted(table.items()):
        print(f"{plant:>5}  " + "  ".join(f"{_cell(by_date.get(d)):>10}" for d in dates))
    if args.csv is not None:
        write_bytes_durably(args.csv, history_csv(observations).encode("utf-8"))
        print(f"CSV -> {args.csv}")
    if args.figures is not None:
        for trait in ("height", "width"):
            png = growth_png(trait, growth_series(observations, trait), f"plot {args.plot}")
            write_bytes_durably(args.figures / f"growth_{trait}.png", png)
        print(f"growth curves -> {args.figures}")
    return 0
