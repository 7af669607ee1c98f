"""The ``fieldapp`` command. Each subcommand is a module of this package with a ``register``
function; modules are found by name, so adding a subcommand touches no other file.

Layers above the core add their subcommands through the ``fieldapp.commands`` entry-point
group (``pyproject.toml``): the core never imports them, yet ``fieldapp gui`` works.

Subcommand modules import their heavy dependencies inside their handlers, so ``--help`` stays
fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Callable, Sequence
from importlib.metadata import entry_points

from fieldapp import __version__
from fieldapp.cli import _blas  # noqa: F401  (before numpy loads: OpenBLAS on one thread)
from fieldapp.errors import FieldappError

Handler = Callable[[argparse.Namespace], int]

PLUGIN_GROUP = "fieldapp.commands"

log = logging.getLogger("fieldapp")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fieldapp",
        description="Maize seedling phenotyping with a Kinect v2 on a turntable on a mobile base.",
    )
    parser.add_argument("--version", action="version", version=f"fieldapp {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        module.register(subparsers)
    for entry in sorted(entry_points(group=PLUGIN_GROUP), key=lambda e: e.name):
        entry.load()(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
    )
    handler: Handler = args.handler
    try:
        return handler(args)
    except FieldappError as error:
        print(f"fieldapp {args.command}: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"fieldapp {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of the output has gone (`fieldapp ... | head`)
        _drop_stdout()
        return EXIT_BROKEN_PIPE


EXIT_BROKEN_PIPE = 128 + 13
"""What a shell reports for a program ended by SIGPIPE, as ``cat file | head`` leaves ``cat``."""


def _drop_stdout() -> None:
    """Point standard output at /dev/null: the interpreter's last flush of what is still
    buffered would otherwise fail on the closed pipe and print a traceback at exit."""
    import os

    try:
        descriptor = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a file (a test's capture)
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, descriptor)
    finally:
        os.close(devnull)
