"""``fieldapp report RESULTS_DIR --out report.html``: one self-contained HTML report."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "report",
        help="one self-contained HTML report of a reconstruction",
        description="Session summary, calibration used, registration quality, plant table, "
        "top-down map, figures and warnings in one HTML file (images embedded).",
    )
    parser.add_argument("results", type=Path, help="the reconstruction's output folder")
    parser.add_argument("--out", type=Path, required=True, help="the HTML file to write")
    parser.add_argument("--session", type=Path, help="the session folder (for its calibration)")
    parser.add_argument("--db", type=Path, help="results database to look the session up in")
    reference = parser.add_mutually_exclusive_group()
    reference.add_argument("--manual", type=Path, help="add the accuracy against manual.csv")
    reference.add_argument("--truth", type=Path, help="add the accuracy against truth.json")
    parser.add_argument(
        "--manual-leaves",
        type=Path,
        help="add the organ accuracy against hand-measured leaves (leaves.csv's columns); "
        "with --truth the organs are compared with the truth's",
    )
    parser.set_defaults(handler=run)


def _inputs(args: argparse.Namespace) -> Any:
    from fieldapp.evaluate.references import load_truth, pair_with_manual, pair_with_truth
    from fieldapp.evaluate.report import ReportInputs
    from fieldapp.evaluate.traits import evaluate_traits
    from fieldapp.results.files import read_manual_csv, read_plants_csv

    inputs = ReportInputs()
    if args.session is not None:
        from fieldapp.io.session import load_session

        session = load_session(args.session, allow_empty=True)
        inputs.calibration = session.calibration.to_document()
        inputs.session_lines = [
            f"captures: {len(session.captures)}",
            f"missing captures: {len(session.missing())}",
            f"created: {session.document.created or '-'}",
        ]
    elif args.db is not None and args.db.exists():
        from fieldapp.results.db import ResultsDB

        with ResultsDB.open(args.db, create=False) as db:
            run = db.run_of_results_dir(args.results)
            if run is not None:
                inputs.calibration = db.session_calibration(run.session_id)
                inputs.session_lines = [f"plot: {run.plot}", f"date: {run.date}"]
    if args.manual is not None or args.truth is not None:
        plants = read_plants_csv(args.results / "plants.csv")
        if args.manual is not None:
            pairing = pair_with_manual(plants, read_manual_csv(args.manual))
        else:
            pairing = pair_with_truth(plants, load_truth(args.truth).plants, 0.15)
        inputs.evaluation = evaluate_traits(pairing)
        inputs.warnings += pairing.warnings()
    _organ_inputs(args, inputs)
    return inputs


def _organ_inputs(args: argparse.Namespace, inputs: Any) -> None:
    """The organ accuracy (same evaluation as ``fieldapp evaluate organs``) when the results
    have leaves and a reference is given."""
    from fieldapp.evaluate.organ_files import evaluate_organ_references

    manual = args.manual_leaves
    truth = args.truth if manual is None else None
    if manual is None and (truth is None or not (args.results / "leaves.csv").is_file()):
        return  # a truth without leaves measured: no organs to compare
    inputs.organ_evaluation, warnings = evaluate_organ_references(args.results, truth, manual)
    inputs.warnings += warnings


def run(args: argparse.Namespace) -> int:
    from fieldapp.evaluate.report import build_report
    from fieldapp.io.durable import write_bytes_durably

    text = build_report(args.results, _inputs(args))
    write_bytes_durably(args.out, text.encode("utf-8"))
    print(f"report -> {args.out} ({len(text) // 1024} kB)")
    return 0
