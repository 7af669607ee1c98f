"""Manual corrections of plants on a small labelled plot made here (two synthetic seedlings):
merge, split by stems, delete, renumber, undo, re-application after a new reconstruction, and a
bad corrections file named by file and field."""

from __future__ import annotations

import datetime as dt
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from fieldapp.errors import FormatError
from fieldapp.recon.organ_traits import foot_m, measure_organs
from fieldapp.recon.outputs import read_labelled_ply
from fieldapp.results.corrected import (
    AUTO_PLANTS,
    CorrectionError,
    add_correction,
    apply_corrections,
    undo_correction,
)
from fieldapp.results.corrections import (
    Corrections,
    Delete,
    Merge,
    PlantRef,
    Relabel,
    Split,
    load_corrections,
    read_corrections,
)
from fieldapp.results.db import ResultsDB
from fieldapp.results.organ_tables import read_table
from fieldapp.results.schema import connect, migrate

from .seedlings import STEMS, apart_and_merged, seedlings, traits_of, write_plot


@pytest.fixture(scope="module")
def auto_plots(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two automatic results of the same plot: plants apart (1, 2) and both as one plant."""
    return apart_and_merged(tmp_path_factory.mktemp("corrections"))


@pytest.fixture
def apart(auto_plots: dict[str, Path], tmp_path: Path) -> Path:
    return Path(shutil.copytree(auto_plots["apart"], tmp_path / "apart"))


@pytest.fixture
def merged(auto_plots: dict[str, Path], tmp_path: Path) -> Path:
    return Path(shutil.copytree(auto_plots["merged"], tmp_path / "merged"))


def _csv(folder: Path, name: str = "plants.csv") -> dict[int, dict]:  # type: ignore[type-arg]
    return {int(r["plant"]): r for r in read_table(folder / name, ("plant",))}


def _ref(folder: Path, plant: int) -> PlantRef:
    cloud, labels = read_labelled_ply(folder / "cloud.ply")
    assert labels is not None
    xy = cloud.points[labels.plant_id == plant, :2].mean(axis=0)
    return PlantRef(plant=plant, xy_m=(float(xy[0]), float(xy[1])))


def _close_to_traits(row: dict, points: NDArray[np.float64]) -> None:  # type: ignore[type-arg]
    traits = traits_of(points)
    assert row["height_cm"] == pytest.approx(100 * traits.height_m, abs=0.011)
    assert row["width_cm"] == pytest.approx(100 * traits.width_m, abs=0.006)
    assert row["x_m"] == pytest.approx(traits.x_m, abs=6e-5)
    assert row["points"] == len(points)


def test_merge_recomputes_traits_with_the_reconstructions_code(apart: Path) -> None:
    merge = Merge(plants=[_ref(apart, 1), _ref(apart, 2)], into=1, author="tester")
    result = add_correction(apart, Corrections(session="s1"), merge)
    rows = _csv(apart)
    assert list(rows) == [1]
    _close_to_traits(rows[1], np.concatenate(seedlings(0)))
    organs = measure_organs(
        np.concatenate(seedlings(0)), foot_m(traits_of(np.concatenate(seedlings(0))))
    )
    assert rows[1]["leaf_count"] == organs.leaf_count
    assert not (apart / "plants" / "2.ply").exists()
    assert result.corrections.applied is not None
    assert result.corrections.applied.corrected == [1]
    assert _csv(apart, AUTO_PLANTS).keys() == {1, 2}  # the automatic result is kept
    saved = read_corrections(apart)
    assert saved is not None and saved.operations[0].author == "tester"


def test_split_by_stems_gives_each_seedling_its_points(merged: Path) -> None:
    split = Split(plant=_ref(merged, 1), stems_xy_m=[STEMS[1], STEMS[0]], into=[1, 2])
    add_correction(merged, Corrections(), split)
    rows = _csv(merged)
    assert list(rows) == [1, 2]
    a, b = seedlings(0)
    _close_to_traits(rows[1], b)  # the first stem picked keeps the plant's number
    _close_to_traits(rows[2], a)
    leaves = read_table(merged / "leaves.csv", ("plant_id",))
    assert {int(r["plant_id"]) for r in leaves} <= {1, 2}


def test_a_stem_picked_off_the_plant_is_refused_and_nothing_written(merged: Path) -> None:
    before = (merged / "plants.csv").read_bytes()
    split = Split(plant=_ref(merged, 1), stems_xy_m=[STEMS[0], (1.0, 1.0)], into=[1, 2])
    with pytest.raises(CorrectionError, match="from plant 1"):
        add_correction(merged, Corrections(), split)
    assert (merged / "plants.csv").read_bytes() == before
    assert read_corrections(merged) is None


def test_delete_relabel_and_undo(apart: Path) -> None:
    auto = (apart / "plants.csv").read_text()
    first = add_correction(apart, Corrections(), Delete(plant=_ref(apart, 2)))
    assert list(_csv(apart)) == [1]
    cloud, labels = read_labelled_ply(apart / "cloud.ply")
    assert labels is not None and not (labels.plant_id == 2).any() and len(cloud) > 6000 - 1
    second = add_correction(apart, first.corrections, Relabel(plant=_ref(apart, 1), into=7))
    rows = _csv(apart)
    assert list(rows) == [7]
    assert rows[7]["height_cm"] == _csv(apart, AUTO_PLANTS)[1]["height_cm"]  # not remeasured
    assert {int(r["plant_id"]) for r in read_table(apart / "leaves.csv", ("plant_id",))} == {7}
    assert (apart / "plants" / "7.ply").is_file() and not (apart / "plants" / "1.ply").exists()
    undone = undo_correction(apart, second.corrections)
    assert list(_csv(apart)) == [1]
    undo_correction(apart, undone.corrections)
    assert (apart / "plants.csv").read_text() == auto
    assert load_corrections(apart / "corrections.json").operations == []


def test_renumbering_onto_a_taken_number_is_refused(apart: Path) -> None:
    with pytest.raises(CorrectionError, match="taken"):
        add_correction(apart, Corrections(), Relabel(plant=_ref(apart, 1), into=2))


def test_a_new_reconstruction_gets_the_corrections_again_by_position(apart: Path) -> None:
    merge = Merge(plants=[_ref(apart, 1), _ref(apart, 2)], into=2)
    phantom = Delete(plant=PlantRef(plant=5, xy_m=(2.0, 2.0)))
    saved = add_correction(apart, Corrections(), merge).corrections
    saved = saved.adding(phantom)
    # a new run into the same folder numbers the plants the other way round, 5 mm apart
    a, b = seedlings(0)
    shift = np.array([0.005, 0.0, 0.0])
    write_plot(apart, [b + shift, a + shift], [1, 2])
    result = apply_corrections(apart, saved)
    rows = _csv(apart)
    assert list(rows) == [1]  # plant 2 then is plant 1 now: the kept number follows the plant
    _close_to_traits(rows[1], np.concatenate([b, a]) + shift)
    applied = result.corrections.applied
    assert applied is not None and len(applied.unmatched) == 1
    assert "operation 2 (delete plant 5)" in applied.unmatched[0]
    assert len(load_corrections(apart / "corrections.json").operations) == 2  # kept
    assert _csv(apart, AUTO_PLANTS).keys() == {1, 2}  # the new automatic result is kept


def test_corrections_carried_to_a_new_results_folder(apart: Path, tmp_path: Path) -> None:
    saved = add_correction(apart, Corrections(), Delete(plant=_ref(apart, 1))).corrections
    other = write_plot(tmp_path / "rerun", seedlings(0)[::-1], [1, 2])
    apply_corrections(other, saved.model_copy(update={"applied": None}))
    rows = _csv(other)
    assert list(rows) == [1] and rows[1]["x_m"] == pytest.approx(STEMS[1][0], abs=0.02)


@pytest.mark.parametrize(
    ("document", "field"),
    [
        ({"operations": [{"kind": "merge", "plants": [], "into": 1}]}, "operations[0].merge"),
        ({"operations": [{"kind": "delete", "plant": {"plant": 0, "xy_m": [0, 0]}}]}, "plant"),
        ({"operations": [{"kind": "squash"}]}, "operations[0]"),
        ({"format": "other/1"}, "format"),
    ],
)
def test_a_bad_corrections_file_names_the_file_and_the_field(
    tmp_path: Path,
    document: dict,
    field: str,  # type: ignore[type-arg]
) -> None:
    path = tmp_path / "corrections.json"
    path.write_text(json.dumps(document))
    with pytest.raises(FormatError) as error:
        load_corrections(path)
    assert str(path) in str(error.value) and field in str(error.value)


def test_the_database_keeps_corrected_traits_and_the_corrections(
    apart: Path, tmp_path: Path
) -> None:
    path = tmp_path / "results.sqlite"
    connection = connect(path)
    migrate(connection, path, target=3)  # a database from before corrections
    connection.close()
    with ResultsDB.open(path) as db:
        run = db.record_run("plot", None, apart, date=dt.date(2026, 6, 1))
        assert db.corrected_plants(run) == [] and db.corrections("s1") is None
        merge = Merge(plants=[_ref(apart, 1), _ref(apart, 2)], into=1)
        add_correction(apart, Corrections(session="s1"), merge)
        assert db.save_corrections("s1", apart) == run
        history = db.history("plot")
        assert [(o.plant_number, o.run_id) for o in history] == [(1, run)]
        assert history[0].height_cm == pytest.approx(_csv(apart)[1]["height_cm"])
        assert db.corrected_plants(run) == [1]
        saved = db.corrections("s1")
        assert saved is not None and saved[0] == apart.resolve()
        assert saved[1]["operations"][0]["kind"] == "merge"
        again = db.record_run("plot", None, apart, date=dt.date(2026, 6, 1))
        assert db.corrected_plants(again) == [1]  # recorded from a corrected folder
        write_plot(apart, seedlings(0), [1, 2])  # reconstructed again, not yet corrected again
        rerun = db.record_run("plot", None, apart, date=dt.date(2026, 6, 1))
        assert db.corrected_plants(rerun) == []
        assert len(db.history("plot")) == 2  # both seedlings, as the reconstruction found them


def test_the_command_line_applies_again_carries_over_and_undoes(
    apart: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from fieldapp.cli import main

    add_correction(apart, Corrections(), Delete(plant=_ref(apart, 1), author="ana"))
    a, b = seedlings(0)
    write_plot(apart, [b, a], [1, 2])  # `fieldapp reconstruct` into the same folder
    assert main(["correct", str(apart)]) == 0
    assert list(_csv(apart)) == [1] and "1. delete plant 1" in capsys.readouterr().out
    other = write_plot(tmp_path / "other", [a, b], [1, 2])
    assert main(["correct", str(other), "--from", str(apart)]) == 0
    assert list(_csv(other)) == [2]
    assert main(["correct", str(other), "--undo"]) == 0
    assert list(_csv(other)) == [1, 2]
    assert main(["correct", str(tmp_path)]) == 1
    assert "no corrections.json" in capsys.readouterr().err
