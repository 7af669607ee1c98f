"""Simulated sessions with known truth, generated once per test run."""

from __future__ import annotations

import json
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.settings import ReconstructionSettings

if TYPE_CHECKING:  # the root conftest's built_once fixture
    from ...conftest import OnceBuilder


@dataclass(frozen=True)
class Simulated:
    folder: Path
    truth: dict[str, Any]


@pytest.fixture(scope="session")
def plot_session(built_once: OnceBuilder) -> Simulated:
    """The standard 9 x 8 plot session (seed 0, day 0) with its truth.json (simulated once per
    run; every worker reads the same folder)."""

    def build(folder: Path) -> None:
        assert main(["simulate", "--out", str(folder / "plot"), "--seed", "0"]) == 0

    folder = built_once("recon-plot", build) / "plot"
    return Simulated(folder, json.loads((folder / "truth.json").read_text()))


@pytest.fixture(scope="session")
def reconstruction(plot_session: Simulated, built_once: OnceBuilder) -> Reconstruction:
    """The plot reconstructed with the default settings, once per run: the workers read the
    same result (pickled)."""

    def build(folder: Path) -> None:
        result = run_reconstruction(load_session(plot_session.folder), ReconstructionSettings())
        (folder / "reconstruction.pickle").write_bytes(pickle.dumps(result))

    folder = built_once("recon-plot-reconstruction", build)
    loaded = pickle.loads((folder / "reconstruction.pickle").read_bytes())
    assert isinstance(loaded, Reconstruction)
    return loaded
