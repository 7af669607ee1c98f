"""Twelve tiny simulated sessions and their one-by-one reconstructions, made once per run.

Two fixtures, so that the first tests to use them (cheap ones) share the set-up time between
them under the per-test timeout."""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from fieldapp.cli import main
from fieldapp.io.session import load_session

if TYPE_CHECKING:  # the root conftest's built_once fixture
    from ...conftest import OnceBuilder

SEEDS = range(12)


def stations(seed: int) -> str:
    """Two stations (ICP between them) for even seeds, one for odd seeds: tiny but varied."""
    return "4,5" if seed % 2 == 0 else "5"


@dataclass(frozen=True)
class Sessions:
    """``folders`` in seed order; ``one_by_one[session id]``: ``fieldapp reconstruct``'s
    output folder for that session (default settings, one thread), run one after the other."""

    folders: list[Path]
    one_by_one: dict[str, Path]
    no_settings: Path


def quietly(argv: list[str]) -> int:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return main(argv)


@dataclass(frozen=True)
class Simulated:
    """The session folders in seed order, and a settings file that does not exist."""

    folders: list[Path]
    no_settings: Path


@pytest.fixture(scope="session")
def simulated(built_once: OnceBuilder) -> Simulated:
    """The twelve sessions, simulated once per run (every worker reads the same folders)."""

    def build(root: Path) -> None:
        for seed in SEEDS:
            folder = root / f"s{seed:02d}"
            argv = ["simulate", "--out", str(folder), "--stations", stations(seed), "--views"]
            assert quietly([*argv, "0-3", "--seed", str(seed)]) == 0

    root = built_once("batch-sessions", build)
    folders = [root / f"s{seed:02d}" for seed in SEEDS]
    return Simulated(folders, root.parent / "batch-no-settings.yaml")


@pytest.fixture(scope="session")
def sessions(simulated: Simulated, built_once: OnceBuilder) -> Sessions:
    """The simulated sessions, each reconstructed by ``fieldapp reconstruct`` in turn with
    the batch's settings: the defaults with one thread (with two, ICP's parallel sums vary in
    their last bits from run to run, and now and then a point lands in another voxel)."""

    def build(root: Path) -> None:
        one_thread = root / "one-thread.yaml"
        one_thread.write_text("reconstruction:\n  threads: 1\n", encoding="utf-8")
        for folder in simulated.folders:
            argv = ["reconstruct", str(folder), "--out", str(root / folder.name), "--quiet"]
            assert quietly([*argv, "--settings", str(one_thread)]) == 0

    root = built_once("batch-one-by-one", build)
    one_by_one = {load_session(f).id: root / f.name for f in simulated.folders}
    return Sessions(simulated.folders, one_by_one, simulated.no_settings)


@pytest.fixture
def no_user_settings(simulated: Simulated, monkeypatch: pytest.MonkeyPatch) -> Path:
    """``FIELDAPP_SETTINGS`` pointing at no file: the defaults, whatever the user has."""
    monkeypatch.setenv("FIELDAPP_SETTINGS", str(simulated.no_settings))
    for name in ("FIELDAPP_RECONSTRUCTION__THREADS", "FIELDAPP_PATHS__RESULTS_DB"):
        monkeypatch.delenv(name, raising=False)
    return simulated.no_settings
