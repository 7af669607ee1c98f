"""A worker process killed mid-batch: its session runs again elsewhere, every session is
done and recorded exactly once."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from fieldapp import __version__
from fieldapp.batch.cluster import open_client
from fieldapp.batch.plan import plan_batch, task_settings
from fieldapp.batch.runner import Outcome, run_batch
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.db import ResultsDB

from .conftest import Sessions

pytestmark = pytest.mark.slow


def test_killing_a_worker_mid_batch_still_does_every_session_once(
    sessions: Sessions, tmp_path: Path
):
    out = tmp_path / "out"
    killed: dict[str, int] = {}  # session id -> pid of the worker killed while running it
    outcomes: list[Outcome] = []
    with ResultsDB.open(tmp_path / "results.sqlite") as db, open_client(None, 2, "2GiB") as client:
        plan = plan_batch(
            sessions.folders, task_settings(ReconstructionSettings()), __version__, db, out
        )
        pids: dict[str, int] = client.run(os.getpid)

        def kill_once(outcome: Outcome) -> None:
            outcomes.append(outcome)
            if killed:
                return
            for address, keys in client.processing().items():
                if keys and address in pids:
                    running = plan.to_run[int(str(keys[0]).rsplit("-", 1)[1])]
                    os.kill(pids[address], signal.SIGKILL)
                    killed[running.session_id] = pids[address]
                    return

        run_batch(client, plan, out, db, on_outcome=kill_once)
        runs = db.runs()
    assert len(killed) == 1, "no worker was busy when the first session ended"
    assert [o.status for o in outcomes] == ["done"] * 12
    assert sorted(o.item.session_id for o in outcomes) == sorted(sessions.one_by_one)
    assert sorted(r.session_id for r in runs) == sorted(sessions.one_by_one)  # once each
    assert {r.status for r in runs} == {"complete"}
    [(session_id, pid)] = killed.items()
    rerun = next(o for o in outcomes if o.item.session_id == session_id)
    assert not rerun.worker.endswith(f":{pid}")  # it ran again, on another process
    for session_id, reference in sessions.one_by_one.items():
        assert (out / session_id / "plants.csv").read_bytes() == (
            reference / "plants.csv"
        ).read_bytes()
