"""``fieldapp correct RESULTS``: manual corrections of plants from the command line: list them,
apply them again after ``fieldapp reconstruct`` rewrote the folder, carry them over from
another results folder of the session, undo the last one (docs/WORKSTATION.md)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "correct",
        help="apply, carry over, list or undo manual corrections of plants",
        description="Manual corrections of a results folder (corrections.json, made in the "
        "results panel). Without options: apply them again (after a new reconstruction into "
        "the folder the plants are found again by position) and list them.",
    )
    parser.add_argument("results", type=Path, help="the results folder")
    parser.add_argument(
        "--from",
        dest="source",
        type=Path,
        help="take the corrections of this results folder (or corrections.json) of the session",
    )
    parser.add_argument("--undo", action="store_true", help="drop the last correction")
    parser.add_argument("--list", action="store_true", help="list them, change nothing")
    parser.add_argument("--settings", type=Path, help="settings YAML (default: the user's)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fieldapp.errors import FieldappError
    from fieldapp.results.corrected import apply_corrections, undo_correction
    from fieldapp.results.corrections import describe, load_corrections, read_corrections
    from fieldapp.settings import load_settings

    if args.source is not None:
        path = args.source / "corrections.json" if args.source.is_dir() else args.source
        corrections = load_corrections(path).model_copy(update={"applied": None})
    else:
        found = read_corrections(args.results)
        if found is None:
            raise FieldappError(f"{args.results}: no corrections.json")
        corrections = found
    if not args.list:
        settings = load_settings(args.settings).reconstruction
        change = undo_correction if args.undo else apply_corrections
        corrections = change(args.results, corrections, settings).corrections
    for number, operation in enumerate(corrections.operations, start=1):
        by = f" by {operation.author}" if operation.author else ""
        print(f"{number}. {describe(operation)} ({operation.time:%Y-%m-%d %H:%M}{by})")
    applied = corrections.applied
    for line in applied.unmatched if applied is not None else []:
        print(f"not applied: {line}")
    return 0
