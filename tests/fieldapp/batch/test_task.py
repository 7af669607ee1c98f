"""The task a worker runs, called here in the test process."""

from __future__ import annotations

import os
import pickle
from pathlib import Path

import pytest

from fieldapp import __version__
from fieldapp.batch.plan import task_settings
from fieldapp.batch.task import BatchError, reconstruct_session, results_folder
from fieldapp.io.session import load_session
from fieldapp.recon.settings import ReconstructionSettings

from .conftest import Sessions

SETTINGS = task_settings(ReconstructionSettings())


def test_a_session_s_outputs_are_those_of_fieldapp_reconstruct(sessions: Sessions, tmp_path):
    folder = sessions.folders[3]
    session_id = load_session(folder).id
    summary = reconstruct_session(str(folder), SETTINGS, str(tmp_path))
    assert summary.ok, summary.message
    assert summary.session_id == session_id
    assert Path(summary.results_dir) == tmp_path / session_id
    reference = sessions.one_by_one[session_id]
    for name in ("plants.csv", "cloud.ply"):
        assert (tmp_path / session_id / name).read_bytes() == (reference / name).read_bytes()
    rows = (reference / "plants.csv").read_text().splitlines()
    assert summary.plants == len(rows) - 1 > 0
    assert summary.worker.endswith(f":{os.getpid()}")
    assert summary.software_version == __version__
    assert summary.cpu_s > 0 and summary.wall_s > 0
    assert pickle.loads(pickle.dumps(summary)) == summary  # travels back to the client


def test_bad_settings_and_missing_folders_fail_with_the_reason(sessions: Sessions, tmp_path):
    bad = SETTINGS | {"crop": {"radius_m": -1.0}}
    summary = reconstruct_session(str(sessions.folders[0]), bad, str(tmp_path))
    assert not summary.ok and "ValidationError" in summary.message
    assert "radius_m" in summary.message
    missing = tmp_path / "missing"
    summary = reconstruct_session(str(missing), SETTINGS, str(tmp_path))
    assert not summary.ok and summary.results_dir == "" and summary.plants == 0
    assert str(missing) in summary.message and "no such folder" in summary.message
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("session_id", ["", ".", "..", "a/b", "a\\b", "x\ny"])
def test_ids_that_cannot_name_a_folder_are_refused(session_id: str, tmp_path: Path):
    with pytest.raises(BatchError, match="cannot name a results folder"):
        results_folder(tmp_path, session_id)


def test_ordinary_ids_name_a_folder_under_the_output(tmp_path: Path):
    assert results_folder(tmp_path, "2022-06-07-plot-a") == tmp_path / "2022-06-07-plot-a"
