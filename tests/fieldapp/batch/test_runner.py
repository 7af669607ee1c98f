"""Twelve sessions on a local cluster of two workers: the same results as one by one, each run
recorded once on the client, skipped when run again; a failing session stops nothing."""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path

import pytest

from fieldapp import __version__
from fieldapp.batch.cluster import open_client
from fieldapp.batch.plan import plan_batch, task_settings
from fieldapp.batch.runner import BatchStatus, Outcome, run_batch
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.db import ResultsDB

from .conftest import Sessions

pytestmark = pytest.mark.slow

OUTPUT_FILES = ("plants.csv", "cloud.ply")


def assert_same_outputs(batch_dir: Path, reference_dir: Path) -> None:
    for name in OUTPUT_FILES:
        assert (batch_dir / name).read_bytes() == (reference_dir / name).read_bytes(), name
    plants = sorted(p.name for p in (reference_dir / "plants").glob("*.ply"))
    assert sorted(p.name for p in (batch_dir / "plants").glob("*.ply")) == plants
    for name in plants:
        assert (batch_dir / "plants" / name).read_bytes() == (
            reference_dir / "plants" / name
        ).read_bytes()


def assert_one_session_at_a_time_per_worker(client) -> None:
    """Two worker processes of one thread, 2 GiB each, one thread for OpenMP and BLAS,
    fieldapp's warnings left to the reports."""
    assert sorted(client.nthreads().values()) == [1, 1]
    assert len(set(client.run(os.getpid).values())) == 2
    assert set(client.run(os.environ.get, "OMP_NUM_THREADS").values()) == {"1"}
    limits = client.run(lambda dask_worker: dask_worker.memory_manager.memory_limit)
    assert set(limits.values()) == {2 * 2**30}
    levels = client.run(lambda: logging.getLogger("fieldapp").level)
    assert set(levels.values()) == {logging.ERROR}


def broken_copy(source: Path, folder: Path) -> Path:
    """A copy of ``source`` under another id whose depth images are not images."""
    shutil.copytree(source, folder)
    document = json.loads((folder / "session.json").read_text())
    document["id"] = "broken-session"
    (folder / "session.json").write_text(json.dumps(document))
    for capture in document["captures"]:
        (folder / capture["depth"]).write_bytes(b"not a png")
    return folder


def test_twelve_sessions_on_two_workers_match_one_by_one(sessions: Sessions, tmp_path: Path):
    out, settings = tmp_path / "out", task_settings(ReconstructionSettings())
    broken = broken_copy(sessions.folders[0], tmp_path / "broken")
    folders = [*sessions.folders[:6], broken, *sessions.folders[6:]]
    statuses: list[BatchStatus] = []
    outcomes: list[Outcome] = []
    with ResultsDB.open(tmp_path / "results.sqlite") as db, open_client(None, 2, "2GiB") as client:
        assert_one_session_at_a_time_per_worker(client)
        plan = plan_batch(folders, settings, __version__, db, out)
        assert len(plan.to_run) == 13 and not plan.skipped and not plan.rejected
        returned = run_batch(
            client, plan, out, db, on_status=statuses.append, on_outcome=outcomes.append
        )
        runs = db.runs()
        again = plan_batch(folders, settings, __version__, db, out)
    assert returned == outcomes and len(outcomes) == 13
    failed = [o for o in outcomes if o.status == "failed"]
    assert [o.item.session_id for o in failed] == ["broken-session"]
    assert "NothingUsable" in failed[0].message or "FormatError" in failed[0].message
    for outcome in outcomes:
        session_id = outcome.item.session_id
        if outcome.status == "done":
            assert_same_outputs(out / session_id, sessions.one_by_one[session_id])
    complete = [r for r in runs if r.status == "complete"]
    assert sorted(r.session_id for r in complete) == sorted(sessions.one_by_one)
    assert [r.session_id for r in runs if r.status == "failed"] == ["broken-session"]
    assert statuses[-1] == BatchStatus(13, 12, 1, 0, statuses[-1].elapsed_s)
    assert all(s.running <= 2 for s in statuses)
    # Run again with the same settings and version: everything done is skipped.
    assert sorted(i.session_id for i in again.skipped) == sorted(sessions.one_by_one)
    assert [i.session_id for i in again.to_run] == ["broken-session"]
