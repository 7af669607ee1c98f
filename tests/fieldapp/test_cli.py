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
