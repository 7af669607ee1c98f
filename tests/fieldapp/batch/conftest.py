"""Twelve tiny simulated sessions and their one-by-one reconstructions, made once per run.

Two fixtures, so that the first tests to use them (cheap ones) share the set-up time between
them under the per-test timeout."""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import pytest

from fieldapp.cli import main
from fieldapp.io.session import load_session

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
def simulated(tmp_path_factory: pytest.TempPathFactory) -> Simulated:
    root = tmp_path_factory.mktemp("batch")
    folders = []
    for seed in SEEDS:
        folder = root / "sessions" / f"s{seed:02d}"
        argv = ["simulate", "--out", str(folder), "--stations", stations(seed), "--views", "0-3"]
        assert quietly([*argv, "--seed", str(seed)]) == 0
        folders.append(folder)
    return Simulated(folders, root / "no-settings.yaml")


@pytest.fixture(scope="session")
def sessions(simulated: Simulated, tmp_path_factory: pytest.TempPathFactory) -> Sessions:
    """The simulated sessions, each reconstructed by ``fieldapp reconstruct`` in turn with
    the batch's settings: the defaults with one thread (with two, ICP's parallel sums vary in
    their last bits from run to run, and now and then a point lands in another voxel)."""
    root, one_by_one = tmp_path_factory.mktemp("one-by-one"), {}
    one_thread = root / "one-thread.yaml"
    one_thread.write_text("reconstruction:\n  threads: 1\n", encoding="utf-8")
    for folder in simulated.folders:
        out = root / folder.name
        argv = ["reconstruct", str(folder), "--out", str(out), "--quiet"]
        assert quietly([*argv, "--settings", str(one_thread)]) == 0
        one_by_one[load_session(folder).id] = out
    return Sessions(simulated.folders, one_by_one, simulated.no_settings)


@pytest.fixture
def no_user_settings(simulated: Simulated, monkeypatch: pytest.MonkeyPatch) -> Path:
    """``FIELDAPP_SETTINGS`` pointing at no file: the defaults, whatever the user has."""
    monkeypatch.setenv("FIELDAPP_SETTINGS", str(simulated.no_settings))
    for name in ("FIELDAPP_RECONSTRUCTION__THREADS", "FIELDAPP_PATHS__RESULTS_DB"):
        monkeypatch.delenv(name, raising=False)
    return simulated.no_settings
