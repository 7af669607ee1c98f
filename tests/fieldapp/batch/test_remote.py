"""``fieldapp batch --scheduler`` against a real Dask deployment: a ``dask scheduler`` process
and ``dask worker`` processes (each behind its nanny) started here on loopback, as a cluster
node would run them, not a LocalCluster inside the test's process."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from fieldapp.cli import main

from .conftest import Sessions

pytestmark = pytest.mark.slow

DASK = Path(sys.executable).with_name("dask")


def _start(argv: list[str], log: Path) -> subprocess.Popen[bytes]:
    with log.open("wb") as out:
        return subprocess.Popen(
            argv, stdout=out, stderr=subprocess.STDOUT, start_new_session=True, env=os.environ
        )


def _stop(process: subprocess.Popen[bytes]) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)


def _workers_seen(scheduler_file: Path) -> int:
    from distributed import Client

    with Client(scheduler_file=str(scheduler_file), timeout="10s") as client:
        return len(client.scheduler_info()["workers"])


@pytest.fixture
def dask_cluster(tmp_path: Path) -> Iterator[str]:
    """A scheduler and two single-thread worker processes on 127.0.0.1; yields its address."""
    scheduler_file = tmp_path / "scheduler.json"
    common = ["--no-dashboard", "--host", "127.0.0.1"]
    scheduler = _start(
        [str(DASK), "scheduler", *common, "--port", "0", "--scheduler-file", str(scheduler_file)],
        tmp_path / "scheduler.log",
    )
    workers = None
    try:
        # no deadline of our own: a process that never comes up is a hang, which the per-test
        # timeout reports; one that dies is reported here with its log
        while not scheduler_file.exists():
            assert scheduler.poll() is None, (tmp_path / "scheduler.log").read_text()
            time.sleep(0.1)
        worker_options = ["--nworkers", "2", "--nthreads", "1", "--scheduler-file"]
        workers = _start(
            [str(DASK), "worker", *common, *worker_options, str(scheduler_file)],
            tmp_path / "workers.log",
        )
        while _workers_seen(scheduler_file) < 2:
            assert workers.poll() is None, (tmp_path / "workers.log").read_text()
            time.sleep(0.2)
        yield json.loads(scheduler_file.read_text())["address"]
    finally:
        if workers is not None:
            _stop(workers)
        _stop(scheduler)


def test_batch_on_a_real_scheduler_and_worker_processes(
    sessions: Sessions, no_user_settings: Path, dask_cluster: str, tmp_path: Path, capsys
):
    folders = sessions.folders[:4]
    out = tmp_path / "out"
    argv = ["batch", *map(str, folders), "--out", str(out), "--db", str(tmp_path / "r.sqlite")]
    assert main([*argv, "--scheduler", dask_cluster, "--quiet"]) == 0
    assert "4 done, 0 failed" in capsys.readouterr().out
    for session_id, reference in list(sessions.one_by_one.items())[:4]:
        for name in ("plants.csv", "cloud.ply"):
            written = (out / session_id / name).read_bytes()
            assert written == (reference / name).read_bytes(), f"{session_id}/{name}"
