"""Small simulated sessions; every test under the GUI tests' leak check."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldapp.cli import main


@pytest.fixture(autouse=True)
def _leak_check(no_leaks: None) -> None:
    """Every test here runs under the GUI tests' leak check (``tests/ui/conftest.py``): no
    thread left running, no top-level widget left alive."""


@pytest.fixture(scope="session")
def boards_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("calibration") / "boards"
    args = ["simulate", "--out", str(folder), "--scene", "checkerboard", "--stations", "4,5"]
    assert main([*args, "--views", "0-7", "--intrinsics-images", "12"]) == 0
    return folder
