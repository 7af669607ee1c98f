"""The ``fieldapp`` command as a user meets it."""

from __future__ import annotations

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
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    assert cli.main(["write"]) == cli.EXIT_BROKEN_PIPE
