"""Twelve tiny simulated sessions and their one-by-one reconstructions, made once per run."""

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
    output folder for that session, run one session after the other."""

    folders: list[Path]
    one_by_one: dict[str, Path]
    no_settings: Path


def quietly(argv: list[str]) -> int:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return main(argv)


@pytest.fixture(scope="session")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> Sessions:
    root = tmp_path_factory.mktemp("batch")
    no_settings = root / "no-settings.yaml"  # absent: the default settings, whatever the user's
    folders, one_by_one = [], {}
    for seed in SEEDS:
        folder = root / "sessions" / f"s{seed:02d}"
        argv = ["simulate", "--out", str(folder), "--stations", stations(seed), "--views", "0-3"]
        assert quietly([*argv, "--seed", str(seed)]) == 0
        folders.append(folder)
    for folder in folders:
        out = root / "one-by-one" / folder.name
        argv = ["reconstruct", str(folder), "--out", str(out), "--settings", str(no_settings)]
        assert quietly([*argv, "--quiet"]) == 0
        one_by_one[load_session(folder).id] = out
    return Sessions(folders, one_by_one, no_settings)


@pytest.fixture
def no_user_settings(sessions: Sessions, monkeypatch: pytest.MonkeyPatch) -> Path:
    """``FIELDAPP_SETTINGS`` pointing at no file: the defaults, whatever the user has."""
    monkeypatch.setenv("FIELDAPP_SETTINGS", str(sessions.no_settings))
    for name in ("FIELDAPP_RECONSTRUCTION__THREADS", "FIELDAPP_PATHS__RESULTS_DB"):
        monkeypatch.delenv(name, raising=False)
    return sessions.no_settings
