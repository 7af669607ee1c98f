"""Leaves in the results database: stored by plant (season id) and leaf number on each date,
so a leaf's growth can be followed; old databases migrate with their data."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import pytest

from fieldapp.errors import FormatError
from fieldapp.results.db import ResultsDB
from fieldapp.results.schema import connect, migrate

from .helpers import write_results

BASES = [(0.0, 0.0), (0.8, 0.0), (1.6, 0.0)]


def write_organs(folder: Path, plants: list[int], leaves: list[tuple]) -> None:
    """Add organ columns to ``plants.csv`` (leaf count from ``leaves``) and a ``leaves.csv``."""
    lines = (folder / "plants.csv").read_text().splitlines()
    counts = {p: sum(1 for leaf in leaves if leaf[0] == p) for p in plants}
    out = [lines[0] + ",leaf_count,leaf_area_cm2,stem_diameter_mm"]
    for line in lines[1:]:
        plant = int(line.split(",")[0])
        area = sum(leaf[3] for leaf in leaves if leaf[0] == plant)
        out.append(f"{line},{counts[plant]},{area:.2f},12.50")
    (folder / "plants.csv").write_text("\n".join(out) + "\n")
    rows = [
        "plant_id,leaf_id,length_cm,max_width_cm,area_cm2,angle_from_stem_deg,azimuth_deg,"
        "insertion_height_cm"
    ]
    rows += [f"{p},{k},{length},4.00,{area},40.00,90.00,5.00" for p, k, length, area in leaves]
    (folder / "leaves.csv").write_text("\n".join(rows) + "\n")


def record(db: ResultsDB, tmp_path: Path, day: int, order: list[int], growth: float) -> None:
    rows = [(i + 1, *BASES[k], 30.0, 40.0) for i, k in enumerate(order)]
    folder = write_results(tmp_path / f"day{day}", f"plot-{day}", rows)
    leaves = [
        (i + 1, leaf, 10.0 * (k + 1) + growth, 50.0) for i, k in enumerate(order) for leaf in (1, 2)
    ]
    write_organs(folder, [i + 1 for i in range(len(order))], leaves)
    db.record_run("plot", None, folder, date=dt.date(2026, 6, 1 + day))


def test_a_leaf_is_followed_through_the_season(tmp_path: Path) -> None:
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        record(db, tmp_path, 0, [0, 1, 2], growth=0.0)
        record(db, tmp_path, 5, [2, 0, 1], growth=3.0)  # the plants listed in another order
        history = db.leaf_history("plot")
        assert len(history) == 12
        first = [o for o in history if o.plant_number == 1 and o.leaf_id == 2]
        assert [o.date.day for o in first] == [1, 6]
        assert [o.traits["length_cm"] for o in first] == [10.0, 13.0]  # the same plant, grown
        organs = db.organ_history("plot")
        assert organs[0][2] == {"leaf_count": 2, "leaf_area_cm2": 100.0, "stem_diameter_mm": 12.5}


def test_a_run_without_leaves_records_none(tmp_path: Path) -> None:
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        folder = write_results(tmp_path / "old", "plot-old", [(1, 0.0, 0.0, 30.0, 40.0)])
        db.record_run("plot", None, folder, date=dt.date(2026, 6, 1))
        assert db.leaf_history("plot") == []
        assert db.organ_history("plot")[0][2]["leaf_count"] is None


def test_a_repeated_leaf_is_refused_and_nothing_is_written(tmp_path: Path) -> None:
    folder = write_results(tmp_path / "bad", "plot-bad", [(1, 0.0, 0.0, 30.0, 40.0)])
    write_organs(folder, [1], [(1, 1, 10.0, 50.0), (1, 1, 11.0, 50.0)])
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        with pytest.raises(FormatError, match="plant 1 has leaf 1 twice"):
            db.record_run("plot", None, folder, date=dt.date(2026, 6, 1))
        assert db.runs() == []


def test_a_database_of_version_2_keeps_its_traits(tmp_path: Path) -> None:
    path = tmp_path / "r.sqlite"
    connection = connect(path)
    migrate(connection, path, target=2)
    connection.close()
    with ResultsDB.open(path) as db:  # now at the newest version
        folder = write_results(tmp_path / "d", "plot-d", [(1, 0.0, 0.0, 30.0, 40.0)])
        db.record_run("plot", None, folder, date=dt.date(2026, 6, 1))
        assert db.history("plot")[0].height_cm == 30.0
        columns = {r[1] for r in db.connection.execute("PRAGMA table_info(traits)")}
        assert {"leaf_count", "leaf_area_cm2", "stem_diameter_mm"} <= columns
