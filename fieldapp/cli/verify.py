"""``fieldapp verify SESSION``: check a session folder completely."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "verify",
        help="check a capture session folder against the session format",
        description="Check a session folder completely: session.json and calibration.json "
        "against the spec, a physically possible calibration, every referenced image a regular "
        "file inside the folder, matching its recorded SHA-256, decodable and of the right kind "
        "and size, every matrix rigid. Exit 0 when usable; otherwise one line per problem.",
    )
    parser.add_argument("session", type=Path, help="the session folder")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fieldapp.verify import verify_session

    report = verify_session(args.session)
    for line in report.summary_lines():
        print(line)
    for problem in report.problems:
        print(f"problem: {problem}", file=sys.stderr)
    if report.usable:
        print(f"{args.session}: usable")
        return 0
    print(f"{args.session}: not usable ({len(report.problems)} problems)", file=sys.stderr)
    return 1
