"""``fieldapp reconstruct SESSION --out DIR``: the plot's plants and their traits."""

from __future__ import annotations

import argparse
import atexit
import gc
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Generator

    from fieldapp.recon.progress import Progress
    from fieldapp.recon.result import Reconstruction


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "reconstruct",
        help="reconstruct a capture session and measure its plants",
        description="Reconstruct a session (views, levelling, plant filtering, ICP between "
        "stations, plants, traits) and write plants.csv, cloud.ply, plants/<id>.ply and "
        "report.json into DIR.",
    )
    parser.add_argument("session", type=Path, help="the session folder")
    parser.add_argument("--out", type=Path, required=True, help="folder for the results")
    parser.add_argument("--no-icp", action="store_true", help="keep the coarse station poses")
    parser.add_argument("--settings", type=Path, help="settings YAML (default: the user's)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the results already in DIR (without it, a DIR holding results is refused)",
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    # The interpreter's exit ends with a collection over every object the imports made (SciPy,
    # pydantic): 0.1 s of a 3 x 3 plot's run, after the outputs are on disk. Frozen, they are
    # skipped; an exit handler, so a caller that runs many commands in one process (the
    # tests) keeps collecting until it leaves.
    atexit.register(gc.freeze)
    # Only what reading the stations needs is imported before the session is loaded: the
    # early reader starts on them while this process imports the rest (SciPy, small_gicp).
    from fieldapp.errors import FieldappError, FormatError
    from fieldapp.io.session import load_session
    from fieldapp.recon.early import start_reading
    from fieldapp.recon.outputs import existing_outputs
    from fieldapp.settings import load_settings

    existing = existing_outputs(args.out) if args.out.is_dir() else []
    if existing and not args.overwrite:
        names = ", ".join(p.name for p in existing)
        raise FieldappError(
            f"{args.out}: already holds results ({names}); not overwritten: give --overwrite "
            "to replace them, or another --out"
        )
    settings = load_settings(args.settings).reconstruction
    if args.no_icp:
        settings.registration.enabled = False
    try:
        session = load_session(args.session)
    except FormatError as error:
        for problem in error.problems:
            print(f"problem: {problem}", file=sys.stderr)
        print(
            f"{args.session}: not reconstructed ({len(error.problems)} problems)", file=sys.stderr
        )
        return 1
    early = start_reading(session, settings)
    try:
        from fieldapp.provenance import provenance_of
        from fieldapp.recon.outputs import write_outputs
        from fieldapp.recon.pipeline import reconstruct

        result = _run_with_bar(reconstruct(session, settings, early), args.quiet)
    finally:
        if early is not None:
            early.close()
    try:
        write_outputs(
            args.out,
            result.rows(),
            result.cloud,
            {p.id: p.cloud for p in result.plants},
            result.report(),
            **result.output_extras(),
            provenance=provenance_of(session, settings),
        )
    except OSError as error:
        print(f"{args.out}: cannot write the results: {error.strerror or error}", file=sys.stderr)
        return 1
    for warning in result.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    for line in result.separation_lines():
        if "by geometry" in line:
            print(line)
    print(f"{len(result.plants)} plants -> {args.out / 'plants.csv'}")
    return 0


def _run_with_bar(steps: Generator[Progress, None, Reconstruction], quiet: bool) -> Reconstruction:
    """Run the reconstruction's ``steps`` to their end, with a progress bar unless ``quiet`` or
    the output is not a terminal (a pipe or a log file got a stray blank line from the bar);
    without one rich, 0.07 s of imports, is not loaded."""
    if quiet or not sys.stdout.isatty():
        while True:
            try:
                next(steps)
            except StopIteration as done:
                return done.value  # type: ignore[no-any-return]
    from rich.progress import Progress as Bar

    with Bar(transient=True) as bar:
        task = bar.add_task("reconstructing", total=1.0)
        while True:
            try:
                event = next(steps)
            except StopIteration as done:
                return done.value  # type: ignore[no-any-return]
            bar.update(
                task, completed=event.fraction, description=f"{event.stage}: {event.message}"
            )
