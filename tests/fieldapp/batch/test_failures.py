"""What the client does with tasks that raise or report the wrong thing (an in-process cluster
and stand-in tasks, so that the test sees every call)."""

from __future__ import annotations

import logging
import shutil
from collections.abc import Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from distributed import Client, LocalCluster

from fieldapp.batch.cluster import quiet_dask_logging
from fieldapp.batch.plan import BatchPlan, plan_batch, task_settings
from fieldapp.batch.runner import run_batch
from fieldapp.batch.task import SessionSummary
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.db import ResultsDB

from .conftest import Sessions

VERSION = "1.0"
CALLS: dict[str, int] = {}
FAILING = "sim-plot-seed1-day0"
REFERENCE: dict[str, Path] = {}


def stand_in(session_dir: str, settings: Mapping[str, Any], out_dir: str) -> SessionSummary:
    """Copies the one-by-one outputs; raises for :data:`FAILING`; "2.0" for seed 2."""
    session_id = Path(session_dir).name
    CALLS[session_id] = CALLS.get(session_id, 0) + 1
    if session_id == FAILING:
        raise RuntimeError("the worker ran out of luck")
    target = Path(out_dir) / session_id
    shutil.copytree(REFERENCE[session_id], target)
    version = "2.0" if session_id == "sim-plot-seed2-day0" else VERSION
    plants = len((target / "plants.csv").read_text().splitlines()) - 1
    return SessionSummary(
        session_dir, session_id, True, "", plants, 0, str(target), 0.1, 0.1, "here:1", version
    )


@pytest.fixture
def client() -> Iterator[Client]:
    with (
        quiet_dask_logging(),
        LocalCluster(
            n_workers=1,
            threads_per_worker=1,
            processes=False,
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


def named_after_ids(sessions: Sessions, tmp_path: Path) -> list[Path]:
    """Session folders named after their ids (so that the stand-in knows them)."""
    folders = []
    for session_id, reference in list(sessions.one_by_one.items())[:4]:
        folder = sessions.folders[list(sessions.one_by_one).index(session_id)]
        folders.append(tmp_path / "sessions" / session_id)
        shutil.copytree(folder, folders[-1])
        REFERENCE[session_id] = reference
    return folders


def run(client: Client, plan: BatchPlan, tmp_path: Path, db: ResultsDB, retries: int) -> dict:
    CALLS.clear()
    outcomes = run_batch(client, plan, tmp_path / "out", db, retries=retries, task=stand_in)
    return {o.item.session_id: o for o in outcomes}


def test_a_task_that_raises_is_retried_then_reported_and_stops_nothing(
    client: Client, sessions: Sessions, tmp_path: Path
):
    folders = named_after_ids(sessions, tmp_path)
    settings = task_settings(ReconstructionSettings())
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        plan = plan_batch(folders, settings, VERSION, db, tmp_path / "out")
        outcomes = run(client, plan, tmp_path, db, retries=2)
        runs = {r.session_id: r for r in db.runs()}
    assert CALLS[FAILING] == 3  # the first try and two retries
    assert outcomes[FAILING].status == "failed"
    assert outcomes[FAILING].message == "RuntimeError: the worker ran out of luck"
    assert "install the same version" in outcomes["sim-plot-seed2-day0"].message
    done = {s for s, o in outcomes.items() if o.status == "done"}
    assert done == {"sim-plot-seed0-day0", "sim-plot-seed3-day0"}
    assert all(CALLS[s] == 1 for s in done)
    assert {s: r.status for s, r in runs.items()} == {
        "sim-plot-seed0-day0": "complete",
        FAILING: "failed",
        "sim-plot-seed2-day0": "failed",
        "sim-plot-seed3-day0": "complete",
    }
    assert runs[FAILING].message == "RuntimeError: the worker ran out of luck"
    assert runs["sim-plot-seed0-day0"].plants == outcomes["sim-plot-seed0-day0"].plants > 0


def test_recording_problems_fail_the_session_not_the_batch(
    client: Client, sessions: Sessions, tmp_path: Path
):
    folders = named_after_ids(sessions, tmp_path)
    settings = task_settings(ReconstructionSettings())
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        db.record_run("elsewhere", folders[0], REFERENCE[folders[0].name])
        plan = plan_batch([folders[0], folders[3]], settings, VERSION, db, tmp_path / "out")
        plan.to_run[:] = [replace(item, plot="A") for item in plan.to_run]
        outcomes = run(client, plan, tmp_path, db, retries=0)
    first, last = folders[0].name, folders[3].name
    assert outcomes[first].status == "failed"
    assert "recording the run" in outcomes[first].message
    assert "'elsewhere'" in outcomes[first].message
    assert outcomes[last].status == "done" and outcomes[last].run_id is not None
