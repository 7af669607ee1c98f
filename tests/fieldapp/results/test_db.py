"""The results database: pragmas, migrations, runs in one transaction, identity, history."""

from __future__ import annotations

import datetime as dt
import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from fieldapp.errors import FieldappError, FormatError
from fieldapp.results.db import ResultsDB
from fieldapp.results.schema import SCHEMA_VERSION, ResultsDBError, connect, migrate
from fieldapp.results.sources import settings_hash

from .helpers import grid_plants, write_results

DAYS = (dt.date(2022, 6, 1), dt.date(2022, 6, 6), dt.date(2022, 6, 11))


def record_season(db: ResultsDB, tmp_path: Path) -> np.ndarray:
    """Three dates of a 16-plant plot: plants listed in a different order each time, bases
    moved by up to 2 cm, plant 16 missed on the second date, a weed found on the third."""
    bases = grid_plants(7)
    rng = np.random.default_rng(3)
    for day_index, date in enumerate(DAYS):
        order = rng.permutation(16)
        if day_index == 1:
            order = order[order != 15]
        rows = [
            (i + 1, *(bases[k] + rng.uniform(-0.02, 0.02, 2)), 10.0 + 5 * day_index + k, 20.0 + k)
            for i, k in enumerate(order)
        ]
        if day_index == 2:
            rows.append((99, 0.0, 0.0, 3.0, 2.0))
        folder = write_results(tmp_path / f"day{day_index}", f"plot-a-{date}", rows)
        db.record_run("plot-a", None, folder, date=date)
    return bases


def test_pragmas_and_schema_version(tmp_path):
    with ResultsDB.open(tmp_path / "sub" / "results.sqlite") as db:
        c = db.connection
        assert c.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert c.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
        assert c.execute("PRAGMA foreign_keys").fetchone()[0] == 1
        assert db.schema_version == SCHEMA_VERSION == 5


def test_migrates_an_old_database_step_by_step(tmp_path):
    path = tmp_path / "r.sqlite"
    connection = connect(path)
    assert migrate(connection, path, target=1) == 1
    names = {r[0] for r in connection.execute("SELECT name FROM sqlite_master")}
    assert "runs" in names and "traits_by_plant" not in names
    connection.close()
    with ResultsDB.open(path) as db:
        assert db.schema_version == SCHEMA_VERSION
        names = {r[0] for r in db.connection.execute("SELECT name FROM sqlite_master")}
        assert "traits_by_plant" in names


def test_newer_schema_and_non_database_are_refused(tmp_path):
    path = tmp_path / "r.sqlite"
    sqlite3.connect(path).execute("PRAGMA user_version = 99").connection.close()
    with pytest.raises(ResultsDBError, match="newer"):
        ResultsDB.open(path)
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not a database at all" * 100)
    with pytest.raises(ResultsDBError, match="not a usable results database"):
        ResultsDB.open(junk)
    with pytest.raises(ResultsDBError, match="no results database"):
        ResultsDB.open(tmp_path / "absent.sqlite", create=False)


def test_a_file_refused_is_not_left_open(tmp_path, monkeypatch):
    """The connection to a file that is not a database is closed when it is refused, not left
    to the collector (Python 3.13 warns of an unclosed database, and the suite failed on it in
    whichever later test the collector ran)."""
    from fieldapp.results import schema

    opened, real_connect = [], sqlite3.connect

    def connect(*args, **kwargs):
        opened.append(real_connect(*args, **kwargs))
        return opened[-1]

    monkeypatch.setattr(schema.sqlite3, "connect", connect)
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not a database at all" * 100)
    with pytest.raises(ResultsDBError, match="not a usable results database"):
        ResultsDB.open(junk)
    assert len(opened) == 1
    with pytest.raises(sqlite3.ProgrammingError, match="closed"):
        opened[0].execute("SELECT 1")


def test_one_id_per_plant_all_season(tmp_path):
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        bases = record_season(db, tmp_path)
        history = db.history("plot-a")
    by_plant: dict[int, list] = {}
    for o in history:
        by_plant.setdefault(o.plant_number, []).append(o)
    assert len(by_plant) == 17  # 16 plants and the weed
    weeds = [v for v in by_plant.values() if v[0].x_m == 0.0 and v[0].y_m == 0.0]
    assert [len(v) for v in weeds] == [1] and weeds[0][0].date == DAYS[2]
    for observations in by_plant.values():
        if observations is weeds[0]:
            continue
        positions = np.array([[o.x_m, o.y_m] for o in observations])
        assert np.ptp(positions, axis=0).max() < 0.05  # one plant, not two neighbours
        true = np.linalg.norm(bases - positions[0], axis=1).argmin()
        heights = [o.height_cm for o in observations]
        # the test wrote height 10 + 5 * day + k for grid plant k: same k on every date
        assert [h - 5 * DAYS.index(o.date) for h, o in zip(heights, observations, strict=True)] == [
            10.0 + true
        ] * len(observations)
    counts = sorted(len(v) for v in by_plant.values())
    assert counts == [1, 2] + [3] * 15  # weed once, plant 16 missed once


def test_is_done_and_runs(tmp_path):
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        record_season(db, tmp_path)
        runs = db.runs("plot-a")
        assert [r.date for r in runs] == list(DAYS)
        assert [r.plants for r in runs] == [16, 15, 17]
        key = settings_hash({"voxel_size_m": 0.002})
        assert db.is_done("plot-a-2022-06-06", key, runs[0].software_version)
        assert not db.is_done("plot-a-2022-06-06", settings_hash({}), runs[0].software_version)
        assert not db.is_done("plot-a-2022-06-06", key, "9.9.9")
        assert db.run_of_results_dir(tmp_path / "day2") == runs[2]


def test_a_second_run_of_a_session_replaces_it_in_the_history(tmp_path):
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        folder = write_results(tmp_path / "a", "s1", [(1, 0.0, 0.0, 10.0, 5.0)])
        db.record_run("p", None, folder, date=DAYS[0])
        folder = write_results(tmp_path / "b", "s1", [(1, 0.01, 0.0, 12.0, 5.0)])
        db.record_run("p", None, folder, date=DAYS[0], settings={"other": 1})
        history = db.history("p")
        assert [(o.plant_number, o.height_cm) for o in history] == [(1, 12.0)]
        assert len(db.runs("p")) == 2


def test_conflicts_and_bad_inputs_change_nothing(tmp_path):
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        folder = write_results(tmp_path / "a", "s1", [(1, 0.0, 0.0, 10.0, 5.0)])
        db.record_run("p", None, folder, date=DAYS[0])
        with pytest.raises(ResultsDBError, match="recorded for plot 'p'"):
            db.record_run("q", None, folder, date=DAYS[0])
        with pytest.raises(ResultsDBError, match="recorded on 2022-06-01"):
            db.record_run("p", None, folder, date=DAYS[1])
        with pytest.raises(FieldappError, match="give the date"):
            db.record_run("p", None, write_results(tmp_path / "b", "s2", []))
        (folder / "plants.csv").write_text(
            "plant,x_m,y_m,height_cm,width_cm,points\n1,0,0,ten,5,3\n", encoding="utf-8"
        )
        with pytest.raises(FormatError, match="row 2 column height_cm"):
            db.record_run("p", None, folder, date=DAYS[2])
        assert len(db.runs()) == 1
        assert db.connection.execute("SELECT COUNT(*) FROM plots").fetchone()[0] == 1


def test_failures_and_manual_measurements(tmp_path):
    from fieldapp.results.files import ManualRecord

    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        folder = write_results(tmp_path / "a", "s1", [(1, 0.0, 0.0, 10.0, 5.0)])
        db.record_run("p", None, folder, date=DAYS[0])
        db.add_manual("p", DAYS[0], [ManualRecord(1, 11.0, None)])
        assert db.manual("p") == [(1, DAYS[0], 11.0, None)]
        with pytest.raises(ResultsDBError, match="no plant 7"):
            db.add_manual("p", DAYS[0], [ManualRecord(7, 1.0, 1.0)])
        with pytest.raises(ResultsDBError, match="no plot named"):
            db.history("nowhere")


def test_a_database_of_version_3_keeps_its_runs_and_gains_provenance(tmp_path):
    """Runs recorded before provenance was kept stay, with ``provenance`` None; new runs have it."""
    path = tmp_path / "r.sqlite"
    connection = connect(path)
    assert migrate(connection, path, target=3) == 3
    connection.executescript(
        "INSERT INTO plots (id, name, created) VALUES (1, 'plot-a', '2022-06-01');"
        "INSERT INTO sessions (id, session_id, plot_id, date) VALUES (1, 's1', 1, '2022-06-01');"
        "INSERT INTO runs (id, session_id, recorded, settings, settings_sha256, software_version,"
        " timings, status) VALUES (1, 1, '2022-06-01', '{}', 'abc', '0.0.1', '{}', 'complete');"
        "INSERT INTO plants (id, plot_id, number, first_run_id) VALUES (1, 1, 1, 1);"
        "INSERT INTO traits (run_id, plant_id, run_plant, x_m, y_m, height_cm, width_cm, points)"
        " VALUES (1, 1, 1, 0.5, 0.5, 12.5, 20.0, 900);"
    )
    connection.close()
    with ResultsDB.open(path) as db:
        assert db.schema_version == SCHEMA_VERSION
        (old,) = db.runs()
        assert (old.session_id, old.software_version, old.plants) == ("s1", "0.0.1", 1)
        assert old.provenance is None
        assert [o.height_cm for o in db.history("plot-a")] == [12.5]
        folder = write_results(tmp_path / "new", "s2", [(1, 0.5, 0.51, 15.0, 22.0)])
        document = {"source": {"kind": "real"}, "software": {"commit": "0123abcd"}}
        report = json.loads((folder / "report.json").read_text())
        (folder / "report.json").write_text(json.dumps(report | {"provenance": document}))
        db.record_run("plot-a", None, folder, date=dt.date(2022, 6, 6))
        assert [r.provenance for r in db.runs()] == [None, document]
        assert [(o.plant_number, o.height_cm) for o in db.history("plot-a")] == [
            (1, 12.5),
            (1, 15.0),
        ]
        columns = db.connection.execute("SELECT source, software_commit FROM runs ORDER BY id")
        assert [tuple(r) for r in columns] == [(None, None), ("real", "0123abcd")]
