"""``fieldapp batch`` as a user runs it: local cluster, then an existing scheduler."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from distributed import LocalCluster

from fieldapp.batch.cluster import quiet_dask_logging
from fieldapp.cli import main
from fieldapp.results.db import ResultsDB

from .conftest import Sessions, Simulated

pytestmark = pytest.mark.slow


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--workers", "0"], "--workers: 0 is outside 1..1024"),
        (["--workers", "two"], "--workers: 'two' is not a whole number"),
        (["--retries", "-1"], "--retries: -1 is outside 0..100"),
        (["--memory-limit", "lots"], "--memory-limit: 'lots' is not a size"),
        (["--scheduler", "nonsense"], "--scheduler: cannot reach nonsense"),
    ],
)
def test_bad_options_are_one_line(
    simulated: Simulated, no_user_settings: Path, tmp_path: Path, capsys, option, message
):
    argv = ["batch", str(simulated.folders[0]), "--out", str(tmp_path / "out")]
    assert main([*argv, "--db", str(tmp_path / "r.sqlite"), *option]) == 1
    err = capsys.readouterr().err
    assert f"fieldapp batch: {message}" in err and "Traceback" not in err


def test_local_batch_then_rerun_skips_what_is_done(
    sessions: Sessions, no_user_settings: Path, tmp_path: Path, capsys
):
    folders = [str(f) for f in sessions.folders[:3]]
    db, out = tmp_path / "r.sqlite", tmp_path / "out"
    argv = ["batch", *folders, "--out", str(out), "--db", str(db), "--workers", "1"]
    missing = ["batch", str(tmp_path / "missing"), *argv[1:]]
    assert main([*missing, "--plot", "P1"]) == 1
    captured = capsys.readouterr()
    assert "2 done" not in captured.out and "3 done, 1 failed, 0 already done" in captured.out
    assert f"failed: {tmp_path / 'missing'}: " in captured.err
    assert captured.err.count("done: sim-plot-seed") == 3
    assert "Traceback" not in captured.err and "distributed" not in captured.err
    with ResultsDB.open(db) as results:
        runs = results.runs()
    assert sorted((r.plot, r.session_id, r.status) for r in runs) == [
        ("P1", f"sim-plot-seed{seed}-day0", "complete") for seed in range(3)
    ]
    for run in runs:
        assert run.results_dir == str(out / run.session_id)
    assert main([*argv, "--plot", "P1", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "0 done, 0 failed, 3 already done" in captured.out
    assert captured.err == ""
    with ResultsDB.open(db) as results:
        assert len(results.runs()) == 3


def test_the_same_command_runs_on_an_existing_scheduler(
    sessions: Sessions, no_user_settings: Path, tmp_path: Path, capsys
):
    with (
        quiet_dask_logging(),
        LocalCluster(
            n_workers=1, processes=False, dashboard_address=":0", silence_logs=logging.ERROR
        ) as cluster,
    ):
        argv = ["batch", str(sessions.folders[4]), "--out", str(tmp_path / "out")]
        argv += ["--db", str(tmp_path / "r.sqlite"), "--scheduler", cluster.scheduler_address]
        assert main([*argv, "--quiet"]) == 0
    assert "1 done, 0 failed" in capsys.readouterr().out
    reference = sessions.one_by_one["sim-plot-seed4-day0"] / "plants.csv"
    written = tmp_path / "out" / "sim-plot-seed4-day0" / "plants.csv"
    assert written.read_bytes() == reference.read_bytes()
