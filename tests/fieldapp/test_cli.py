"""The ``fieldapp`` command as a user meets it."""

from __future__ import annotations

import argparse
import subprocess
import sys

from fieldapp import __version__
from fieldapp.cli import build_parser


def test_help_lists_the_subcommands():
    help_text = build_parser().format_help()
    assert "verify" in help_text


def test_python_dash_m_works_and_reports_the_version():
    result = subprocess.run(
        [sys.executable, "-m", "fieldapp", "--version"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0
    assert result.stdout.strip() == f"fieldapp {__version__}"


def test_usage_errors_exit_2_without_traceback():
    result = subprocess.run(
        [sys.executable, "-m", "fieldapp", "no-such-command"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert "invalid choice" in result.stderr
    assert "Traceback" not in result.stderr


def test_output_into_a_closed_pipe_ends_quietly():
    """``fieldapp ... | head``: the reader leaves before the command writes; the command stops
    as one killed by SIGPIPE would (141), without a traceback."""
    process = subprocess.Popen(
        [sys.executable, "-m", "fieldapp", "camera", "info"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    process.stdout.close()  # before the child can write: its first line meets a closed pipe
    _, stderr = process.communicate()
    assert process.returncode == 128 + 13
    assert "Traceback" not in stderr
    assert "BrokenPipeError" not in stderr


def test_a_broken_pipe_in_a_handler_returns_141(monkeypatch):
    import argparse

    import fieldapp.cli as cli

    def handler(_args):
        raise BrokenPipeError

    parser = argparse.ArgumentParser(prog="fieldapp")
    parser.add_argument("-v", "--verbose", action="store_true")
    subparsers = parser.add_subparsers(dest="command", required=True)
    subparsers.add_parser("write").set_defaults(handler=handler)
    monkeypatch.setattr(cli, "build_parser", lambda argv=None: parser)
    assert cli.main(["write"]) == cli.EXIT_BROKEN_PIPE


def _subcommand_parsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    raise AssertionError("no subcommands")


def test_a_command_line_naming_a_subcommand_gets_that_subcommand_as_the_full_parser_has_it():
    """Issue 22 (start-up): only the named subcommand's module is imported; its parser, help
    and handler are those of the parser of every subcommand."""
    every = _subcommand_parsers(build_parser())
    assert {"reconstruct", "import", "sim-base", "verify"} <= set(every)
    for command, full in every.items():
        only = _subcommand_parsers(build_parser([command, "--help"]))
        assert command in only
        assert only[command].format_help() == full.format_help()
        assert only[command].get_default("handler") == full.get_default("handler")


ONE_MODULE = """
import sys
from fieldapp.cli import build_parser

args = build_parser(sys.argv[1:]).parse_args(sys.argv[1:])
loaded = sorted(m for m in sys.modules if m.startswith("fieldapp.cli."))
print(args.command, loaded, "importlib.metadata" in sys.modules)
"""


def test_parsing_a_core_subcommand_imports_neither_the_others_nor_the_entry_points():
    done = subprocess.run(
        [sys.executable, "-c", ONE_MODULE, "-v", "reconstruct", "S", "--out", "O"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [
        "reconstruct",
        "['fieldapp.cli._blas',",
        "'fieldapp.cli.reconstruct']",
        "False",
    ]


def test_a_plugin_command_or_a_mistake_gets_the_parser_of_every_subcommand():
    assert "verify" in _subcommand_parsers(build_parser(["no-such-command"]))
    assert "verify" in _subcommand_parsers(build_parser(["--help"]))
    assert "verify" in _subcommand_parsers(build_parser([]))
