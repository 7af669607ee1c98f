"""What the benchmarks run on one session share: a session named on the command line, or a
plot simulated for the run (``--seed``), each measured ``--repeats`` times."""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from pathlib import Path

from fieldapp.cli import main as fieldapp_main


def main_on_a_session(description: str, run: Callable[[Path, int], None]) -> None:
    """Parse the command line and call ``run(session, repeats)``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--session", type=Path, help="a simulated or real session folder")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated plot")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    if args.session is not None:
        run(args.session, args.repeats)
        return
    with tempfile.TemporaryDirectory() as folder:
        session = Path(folder) / "plot"
        if fieldapp_main(["simulate", "--out", str(session), "--seed", str(args.seed)]) != 0:
            raise SystemExit("fieldapp simulate failed")
        run(session, args.repeats)
