"""The reconstruction in a child process: progress, outputs, cancel, errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from fieldapp.cli import main
from fieldapp.errors import FieldappError
from fieldapp.recon.process import reconstruct_in_process
from fieldapp.recon.settings import ReconstructionSettings


@pytest.fixture(scope="module")
def small_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("process") / "session"
    args = ["simulate", "--out", str(folder), "--seed", "2", "--stations", "5", "--views", "0-3"]
    assert main(args) == 0
    return folder


def test_runs_in_a_child_and_writes_the_outputs(small_session, tmp_path):
    steps = reconstruct_in_process(small_session, ReconstructionSettings(), tmp_path / "out")
    stages = []
    while True:
        try:
            stages.append(next(steps).stage)
        except StopIteration as done:
            summary = done.value
            break
    assert stages
    assert summary["plants"] > 0
    assert (tmp_path / "out" / "plants.csv").is_file()
    assert (tmp_path / "out" / "report.json").is_file()
    rows = (tmp_path / "out" / "plants.csv").read_text().strip().splitlines()
    assert len(rows) == summary["plants"] + 1


def test_closing_cancels_the_child_and_writes_nothing(small_session, tmp_path):
    steps = reconstruct_in_process(small_session, ReconstructionSettings(), tmp_path / "out")
    next(steps)
    steps.close()
    assert not (tmp_path / "out" / "plants.csv").exists()


def test_the_childs_error_reaches_the_caller(tmp_path):
    steps = reconstruct_in_process(tmp_path / "nowhere", ReconstructionSettings(), tmp_path / "o")
    with pytest.raises(FieldappError, match="no such folder"):
        list(steps)


def test_the_child_imports_the_pipeline_after_its_stations_reader_has_started():
    """The spawned child imports ``process`` fresh: SciPy and small_gicp load after
    ``start_reading`` (in ``_child``), so the reader overlaps their import as in the CLI."""
    script = (
        "import sys; import fieldapp.recon.process; "
        "print(sorted(m for m in ('scipy', 'small_gicp', 'fieldapp.recon.pipeline') "
        "if m in sys.modules))"
    )
    command = [sys.executable, "-c", script]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
