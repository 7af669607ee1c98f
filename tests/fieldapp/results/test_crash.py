"""A run killed inside its transaction leaves the database as it was; readers never wait."""

from __future__ import annotations

import datetime as dt
import os
import signal
import subprocess
import sys
import time

from fieldapp.results import schema
from fieldapp.results.db import ResultsDB

from .helpers import grid_plants, write_results

CHILD = """
import datetime as dt, sys, time
from pathlib import Path
import fieldapp.results.db as dbm

original = dbm._insert_traits

def stall(db, run_id, plants, plant_ids):
    original(db, run_id, plants, plant_ids)  # the run, its new plants and traits are written
    Path(sys.argv[3]).write_text("inside the transaction")
    time.sleep(60)

dbm._insert_traits = stall
with dbm.ResultsDB.open(Path(sys.argv[1])) as db:
    db.record_run("plot-a", None, Path(sys.argv[2]), date=dt.date(2022, 6, 11))
"""


def _rows(bases, shift: float) -> list[tuple[int, float, float, float, float]]:
    return [(i + 1, x + shift, y, 20.0, 10.0) for i, (x, y) in enumerate(bases)]


def test_kill_inside_the_transaction(tmp_path, monkeypatch):
    path = tmp_path / "r.sqlite"
    bases = grid_plants(1)
    with ResultsDB.open(path) as db:
        first = write_results(tmp_path / "d1", "s1", _rows(bases[:10], 0.0))
        db.record_run("plot-a", None, first, date=dt.date(2022, 6, 1))
    second = write_results(tmp_path / "d2", "s2", _rows(bases, 0.01))  # 6 new plants
    marker = tmp_path / "inside"
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path), str(second), str(marker)],
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 60
        while not marker.exists():
            assert child.poll() is None, child.stderr.read().decode() if child.stderr else ""
            assert time.monotonic() < deadline, "the child never reached the transaction"
            time.sleep(0.05)
        # a reader while the writer holds its transaction sees the committed state without
        # waiting: with no busy timeout at all, any lock it had to wait for would raise at once
        monkeypatch.setattr(schema, "BUSY_TIMEOUT_MS", 0)
        with ResultsDB.open(path, create=False) as reader:
            assert [r.session_id for r in reader.runs()] == ["s1"]
            assert len(reader.history("plot-a")) == 10
        monkeypatch.undo()
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait(timeout=30)
        if child.stderr:
            child.stderr.close()
    assert child.returncode == -signal.SIGKILL
    with ResultsDB.open(path, create=False) as db:
        assert db.connection.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert db.connection.execute("PRAGMA foreign_key_check").fetchall() == []
        assert [r.session_id for r in db.runs()] == ["s1"]
        assert db.connection.execute("SELECT COUNT(*) FROM plants").fetchone()[0] == 10
        assert db.connection.execute("SELECT COUNT(*) FROM traits").fetchone()[0] == 10
        # the lock died with the writer: the same run can now be recorded
        db.record_run("plot-a", None, second, date=dt.date(2022, 6, 11))
        assert [r.plants for r in db.runs()] == [10, 16]
        assert len({o.plant_number for o in db.history("plot-a")}) == 16
