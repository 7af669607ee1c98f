"""Small simulated sessions; every test under the GUI tests' leak check."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldapp.cli import main


@pytest.fixture(scope="session")
def plot_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("results") / "plot"
    assert main(["simulate", "--out", str(folder), "--stations", "4,5", "--views", "0-3"]) == 0
    return folder


@pytest.fixture(autouse=True)
def _leak_check(no_leaks: None) -> None:
    """Every test here runs under the GUI tests' leak check (``tests/ui/conftest.py``): no
    thread left running, no top-level widget left alive."""
