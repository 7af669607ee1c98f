"""The simulator's second plant model (``--plant-model irregular``) and the first one unchanged."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.sim.organ_truth import organ_truth
from devices.sim.plants import PLANT_MODELS, STEM_PART, make_plant
from devices.sim.plants_irregular import SECTION_VERTICES, STEM_SIDES
from devices.sim.scene import plot_scene
from fieldapp.cli import main


@pytest.mark.parametrize(
    ("stage", "first", "middle", "last", "total"),
    [
        (
            "seedling",
            [0.41044616247461846, -0.7997482722584028, -0.0044347809384220754],
            [0.36870289001512535, -0.7900297152593672, 0.11879447776383947],
            [0.32063608910514385, -0.7605091336571155, 0.41151726551881745],
            -66.76606337202573,
        ),
        (
            "touching",
            [0.41096909690314404, -0.7997356707788628, -0.005257505340695023],
            [0.3386255646834162, -0.8058065388120771, 0.14523128344631459],
            [0.5169829190987699, -0.8891621247378774, 0.7106324007536615],
            -41.91612988676248,
        ),
    ],
)
def test_the_default_model_is_the_first_one_unchanged(
    stage: str, first: list[float], middle: list[float], last: list[float], total: float
) -> None:
    """Vertices of the first model's plant as they were before the second model was added."""
    plant = make_plant(3007, 4, (0.4, -0.8), 0.012, stage)
    again = make_plant(3007, 4, (0.4, -0.8), 0.012, stage, "distichous")
    np.testing.assert_array_equal(plant.vertices_m, again.vertices_m)
    np.testing.assert_allclose(plant.vertices_m[[0, 100, -1]], [first, middle, last], rtol=1e-12)
    assert float(plant.vertices_m.sum()) == pytest.approx(total, rel=1e-12)
    assert (plant.stem_sides, plant.section_vertices) == (8, 3)


@pytest.mark.parametrize("stage", ["seedling", "touching"])
def test_an_irregular_plant_is_the_same_for_the_same_seed(stage: str) -> None:
    a = make_plant(12, 3, (0.1, 0.2), 0.01, stage, "irregular")
    b = make_plant(12, 3, (0.1, 0.2), 0.01, stage, "irregular")
    other = make_plant(13, 3, (0.1, 0.2), 0.01, stage, "irregular")
    np.testing.assert_array_equal(a.vertices_m, b.vertices_m)
    np.testing.assert_array_equal(a.albedo_rgb, b.albedo_rgb)
    assert a.vertices_m.shape != other.vertices_m.shape or not np.array_equal(
        a.vertices_m, other.vertices_m
    )


@pytest.mark.parametrize(
    ("stage", "heights", "leaves"),
    [("seedling", (0.15, 0.55), (4, 7)), ("touching", (0.5, 1.3), (6, 9))],
)
def test_irregular_plants_have_organs_and_sane_truth(
    stage: str, heights: tuple[float, float], leaves: tuple[int, int]
) -> None:
    for seed in range(8):
        plant = make_plant(seed, 0, (0.0, 0.0), 0.0, stage, "irregular")
        assert heights[0] <= plant.height_m <= heights[1]
        assert 0.6 * plant.height_m <= plant.width_m <= 2.5 * plant.height_m
        assert leaves[0] <= plant.leaves <= leaves[1]
        organ = plant.organ_of_vertex
        assert organ is not None
        assert set(np.unique(organ)) == {STEM_PART, *range(plant.leaves)}
        assert (organ == STEM_PART).sum() % STEM_SIDES == 0
        truth = organ_truth(plant)
        assert truth["leaf_count"] == plant.leaves
        assert 5.0 <= truth["stem_diameter_mm"] <= 35.0
        for leaf in truth["leaves"]:
            assert 3.0 <= leaf["length_cm"] <= 100.0
            assert 0.5 <= leaf["max_width_cm"] <= 0.25 * leaf["length_cm"]
            assert 0.0 < leaf["insertion_height_cm"] < 100 * plant.height_m
        albedo = plant.albedo_rgb
        assert np.all(2 * albedo[:, 1] - albedo[:, 0] - albedo[:, 2] > 0.2)  # excess green


def test_irregular_leaves_deviate_from_180_degrees_and_plants_face_any_way() -> None:
    """The first model's touching plants have their leaves along the rows (azimuth within 30
    degrees of the x axis, then 180 degrees apart); the second's point anywhere."""
    facing, deviations = [], []
    for seed in range(16):
        plant = make_plant(seed, 0, (0.0, 0.0), 0.0, "touching", "irregular")
        azimuths = np.array([leaf["azimuth_deg"] for leaf in organ_truth(plant)["leaves"]])
        facing.append(azimuths[0] % 180.0)
        turns = (np.diff(azimuths) - 180.0 + 180.0) % 360.0 - 180.0
        deviations.extend(turns)
    assert np.ptp(facing) > 120.0
    assert 8.0 < np.std(deviations) < 60.0


def test_the_irregular_plot_and_its_truth(tmp_path) -> None:
    scene = plot_scene(0, stage="touching", plant_model="irregular")
    contacts = scene.contacts()
    assert sum(bool(names) for names in contacts.reaching_into.values()) >= 12
    out = tmp_path / "s"
    options = ["--seed", "0", "--plant-model", "irregular", "--stations", "5", "--views", "0"]
    assert main(["simulate", "--out", str(out), *options]) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["plant_model"] == "irregular"
    session = json.loads((out / "session.json").read_text())
    assert "irregular" in json.dumps(session)
    assert all(p["leaves"] and p["leaf_count"] >= 4 for p in truth["plants"])
    assert SECTION_VERTICES == 5 and "irregular" in PLANT_MODELS


def test_the_default_session_does_not_name_a_plant_model(tmp_path) -> None:
    out = tmp_path / "s"
    assert main(["simulate", "--out", str(out), "--stations", "5", "--views", "0"]) == 0
    assert "plant_model" not in json.loads((out / "truth.json").read_text())


def test_the_cli_names_a_bad_plant_model(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--out", str(tmp_path / "s"), "--plant-model", "rice"]) == 1
    assert "--plant-model: 'rice' is not one of distichous, irregular" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()
    with pytest.raises(ValueError, match="plant model"):
        make_plant(1, 0, (0.0, 0.0), 0.0, "seedling", "rice")


@pytest.mark.parametrize("model", PLANT_MODELS)
def test_narrower_leaf_blades_change_the_widths_alone(model: str) -> None:
    """``leaf_width`` (``simulate --leaf-width``): the same plant with its blades that many
    times as wide; the rest of it (its height, how long and where its leaves are) kept."""
    wide = organ_truth(make_plant(21, 0, (0.0, 0.0), 0.0, "seedling", model))
    narrow = organ_truth(make_plant(21, 0, (0.0, 0.0), 0.0, "seedling", model, leaf_width=0.35))
    assert len(narrow["leaves"]) == len(wide["leaves"]) >= 4
    for thin, broad in zip(narrow["leaves"], wide["leaves"], strict=True):
        assert thin["max_width_cm"] == pytest.approx(0.35 * broad["max_width_cm"], rel=0.1)
        assert thin["length_cm"] == pytest.approx(broad["length_cm"], rel=0.03)
        assert thin["insertion_height_cm"] == pytest.approx(broad["insertion_height_cm"], abs=0.5)
    with pytest.raises(ValueError, match="leaf_width"):
        make_plant(21, 0, (0.0, 0.0), 0.0, "seedling", model, leaf_width=0.1)


def test_simulate_records_the_leaf_width_and_refuses_it_off_the_plot(tmp_path: Path) -> None:
    out = tmp_path / "narrow"
    options = ["--grid", "2", "--stations", "1", "--views", "0", "--leaf-width", "0.4"]
    assert main(["simulate", "--out", str(out), *options]) == 0
    assert json.loads((out / "truth.json").read_text())["leaf_width"] == 0.4
    soil = ["simulate", "--out", str(tmp_path / "soil"), "--scene", "soil", "--leaf-width", "0.4"]
    assert main(soil) == 1
