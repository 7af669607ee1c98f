"""The ``fieldapp`` command. Each subcommand is a module of this package with a ``register``
function; modules are found by name, so adding a subcommand touches no other file.

Layers above the core add their subcommands through the ``fieldapp.commands`` entry-point
group (``pyproject.toml``): the core never imports them, yet ``fieldapp gui`` works.

Subcommand modules import their heavy dependencies inside their handlers, so ``--help`` stays
fast. A command line naming one of the core's subcommands imports that module alone (and looks
up no entry points): the others, 30 ms, were start-up that ``fieldapp reconstruct`` waits on
before its station reader starts (issue 22).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Callable, Sequence
from typing import Any

import fieldapp
from fieldapp.cli import _blas  # noqa: F401  (before numpy loads: OpenBLAS on one thread)
from fieldapp.errors import FieldappError

Handler = Callable[[argparse.Namespace], int]

PLUGIN_GROUP = "fieldapp.commands"

log = logging.getLogger("fieldapp")


class _Version(argparse.Action):
    """``--version``: the version is looked up only when asked for (``fieldapp.__version__``)."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, help="show the version and exit")

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> None:
        print(f"fieldapp {fieldapp.__version__}")
        parser.exit()


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The command line's parser; given the arguments, only what parsing them needs: the one
    core subcommand they name (:func:`_named_module`), else every subcommand."""
    modules = sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
    command = _command(argv)
    only = _named_module(command, modules)
    if only is not None:
        parser = _parser([only], plugins=False)
        if command in _subcommands(parser):
            return parser
    return _parser(modules, plugins=True)


def _parser(modules: list[str], plugins: bool) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fieldapp",
        description="Maize seedling phenotyping with a Kinect v2 on a turntable on a mobile base.",
    )
    parser.add_argument("--version", action=_Version)
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in modules:
        module = importlib.import_module(f"{__name__}.{name}")
        module.register(subparsers)
    if plugins:
        from importlib.metadata import entry_points

        for entry in sorted(entry_points(group=PLUGIN_GROUP), key=lambda e: e.name):
            entry.load()(subparsers)
    return parser


def _command(argv: Sequence[str] | None) -> str | None:
    """The subcommand's name: the first argument that is not an option (the options before it,
    ``-v``, ``--version``, ``-h``, take no value)."""
    for argument in sys.argv[1:] if argv is None else argv:
        if not argument.startswith("-"):
            return argument
    return None


def _named_module(command: str | None, modules: list[str]) -> str | None:
    """The core module (of ``modules``) that may hold ``command``: ``sim-base`` ->
    ``sim_base``, ``import`` -> ``import_``; ``None`` when there is none (``--help``, a
    plugin's command, a mistake)."""
    if command is None:
        return None
    name = command.replace("-", "_")
    return next((m for m in (name, name + "_") if m in modules), None)


def _subcommands(parser: argparse.ArgumentParser) -> set[str]:
    return {
        name
        for action in parser._actions
        if isinstance(action, argparse._SubParsersAction)
        for name in action.choices
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit code."""
    parser = build_parser(argv)
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
