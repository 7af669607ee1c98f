"""Simulated sessions with known truth, generated once per test run."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.settings import ReconstructionSettings


@dataclass(frozen=True)
class Simulated:
    folder: Path
    truth: dict[str, Any]


@pytest.fixture(scope="session")
def plot_session(tmp_path_factory: pytest.TempPathFactory) -> Simulated:
    """The standard 9 x 8 plot session (seed 0, day 0) with its truth.json."""
    folder = tmp_path_factory.mktemp("sim") / "plot"
    assert main(["simulate", "--out", str(folder), "--seed", "0"]) == 0
    return Simulated(folder, json.loads((folder / "truth.json").read_text()))


@pytest.fixture(scope="session")
def reconstruction(plot_session: Simulated) -> Reconstruction:
    """The plot reconstructed with the default settings."""
    return run_reconstruction(load_session(plot_session.folder), ReconstructionSettings())
