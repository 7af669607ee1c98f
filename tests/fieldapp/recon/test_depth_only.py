"""Depth-only reconstruction: plants told from the soil by geometry when colour is missing or
has no green contrast, chosen automatically and said in the report and by the CLI."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.recon import geometry_split, stages
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.exg import NO_COLOUR, NO_GREEN_CONTRAST, choose_separation
from fieldapp.recon.filters import filter_station, pass_through
from fieldapp.recon.geometry_split import plants_above_local_ground
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.settings import FilterSettings, PlantSettings, ReconstructionSettings

from .conftest import Simulated
from .test_end_to_end import matched_errors


def test_separation_is_geometry_without_colour_or_green_contrast() -> None:
    rng = np.random.default_rng(0)
    assert choose_separation(None).reason == NO_COLOUR
    constant = np.zeros(10_000)  # ExG of a constant grey image: Otsu's threshold is its value
    assert choose_separation(constant).reason == NO_GREEN_CONTRAST
    noisy_grey = rng.normal(0.0, 0.02, 10_000)  # a grey JPEG's noise
    assert choose_separation(noisy_grey).by_geometry
    plot = np.concatenate([rng.normal(0.0, 0.03, 9_900), rng.normal(0.4, 0.05, 100)])
    separation = choose_separation(plot)
    assert not separation.by_geometry
    assert separation.describe() == "plants separated by colour (excess green)"
    assert choose_separation(None).describe() == "plants separated by geometry: no colour"


def _soil(rng: np.random.Generator) -> np.ndarray:
    """Uneven soil (+-5 cm over the patch) with 2 mm noise, a point every 5 mm."""
    x, y = np.meshgrid(np.arange(-0.6, 0.6, 0.005), np.arange(-0.6, 0.6, 0.005))
    z = 0.03 * np.sin(2 * np.pi * x / 1.2) + 0.02 * np.cos(2 * np.pi * y / 0.9)
    points = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    points[:, 2] += rng.normal(0.0, 0.002, len(points))
    return points


def _ground(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return 0.03 * np.sin(2 * np.pi * x / 1.2) + 0.02 * np.cos(2 * np.pi * y / 0.9)


def _plant(base: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """A stem 25 cm tall and a leaf arching from 15 cm down to 6 mm above the soil 25 cm out;
    returns (stem and leaf points, the leaf's points)."""
    bx, by = base
    g0 = _ground(np.array([bx]), np.array([by]))[0]
    stem = np.column_stack([np.full(200, bx), np.full(200, by), g0 + np.linspace(0.0, 0.25, 200)])
    s = np.linspace(0.0, 1.0, 400)
    across = np.tile(np.linspace(-0.01, 0.01, 5), len(s))
    s = np.repeat(s, 5)
    x, y = bx + 0.25 * s, by + across
    z = (1 - s**2) * (g0 + 0.15) + s**2 * (_ground(x, y) + 0.006)
    leaf = np.column_stack([x, y, z])
    return np.concatenate([stem, leaf]), leaf


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_geometry_keeps_the_plant_down_to_its_leaf_tip_and_drops_uneven_soil(seed: int) -> None:
    rng = np.random.default_rng(seed)
    soil = _soil(rng)
    plant, leaf = _plant((rng.uniform(-0.3, 0.0), rng.uniform(-0.3, 0.3)))
    cx, cy = rng.uniform(0.1, 0.4, 2)  # a clod 1.8 cm high, 3 cm across, away from the plant
    r = np.hypot(soil[:, 0] - cx, soil[:, 1] - cy)
    soil[:, 2] += 0.018 * np.sqrt(np.clip(1 - (r / 0.015) ** 2, 0.0, None))
    clod = r < 0.012
    points = np.concatenate([soil, plant])
    sample = points[::4]  # the sparse grid: every 4th point, plants included
    is_plant, _, _ = plants_above_local_ground(points, sample, soil_band_m=0.15)
    on_plant, on_soil = is_plant[len(soil) :], is_plant[: len(soil)]
    assert on_plant.mean() > 0.95
    kept_leaf = leaf[on_plant[-len(leaf) :]]
    assert kept_leaf[:, 0].max() > leaf[:, 0].max() - 0.02  # the tip, nearly to the soil
    assert not on_soil[clod].any()
    assert on_soil.mean() < 0.001
    # a ground plane cannot do this: the relief puts a third of the soil above 1 cm
    assert pass_through(soil[:, 2] - soil[:, 2].mean(), 0.01, 1.5).mean() > 0.25


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clods_standing_clear_of_the_soil_are_no_plant(seed: int) -> None:
    """A tilled seedbed's clods stand 1-6 cm out of the soil: by geometry alone they were
    plants from 3 cm (a simulated depth-only 2 x 2 plot with clods: 91 "plants" for 4). A
    plant must reach ``PLANT_MIN_M`` (8 cm); the seedling keeps its leaf down to the tip."""
    rng = np.random.default_rng(seed)
    soil = _soil(rng)
    plant, leaf = _plant((rng.uniform(-0.3, 0.0), rng.uniform(-0.3, 0.3)))
    clods = np.zeros(len(soil), dtype=bool)
    for cx, cy, tall in zip(
        rng.uniform(0.32, 0.55, 6),
        rng.uniform(-0.5, 0.5, 6),
        rng.uniform(0.035, 0.06, 6),
        strict=True,
    ):
        r = np.hypot(soil[:, 0] - cx, soil[:, 1] - cy)
        soil[:, 2] += tall * np.sqrt(np.clip(1 - (r / 0.035) ** 2, 0.0, None))
        clods |= r < 0.02
    points = np.concatenate([soil, plant])
    sample = points[::4]
    is_plant, _, _ = plants_above_local_ground(points, sample, soil_band_m=0.15)
    assert not is_plant[: len(soil)][clods].any()
    assert is_plant[len(soil) :].mean() > 0.95
    kept_leaf = leaf[is_plant[-len(leaf) :]]
    assert kept_leaf[:, 0].max() > leaf[:, 0].max() - 0.02
    lower, _, _ = plants_above_local_ground(points, sample, 0.15, plant_min_m=0.03)
    assert lower[: len(soil)][clods].any()  # the bar of before: the clods were plants


def _clod(
    soil: np.ndarray, centre: tuple[float, float], across_m: float, tall_m: float
) -> np.ndarray:
    """Raise a dome ``across_m`` wide and ``tall_m`` high out of ``soil`` (in place); returns
    which soil points stand more than 1.5 cm out of it: the clod's top."""
    r = np.hypot(soil[:, 0] - centre[0], soil[:, 1] - centre[1]) / (across_m / 2)
    rise = tall_m * np.clip(1 - r**2, 0.0, None)
    soil[:, 2] += rise
    return rise > 0.015  # type: ignore[no-any-return]


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_the_top_of_a_clod_a_low_leaf_rests_on_is_no_plant(seed, monkeypatch) -> None:
    """A coarse seedbed's clod, 9 cm across and 3 cm high, under a seedling's leaf tip: joined
    through the leaf it was part of the plant, its far side setting the plant's width (the
    sixth renderer's seedlings without colour: plants up to 13.5 cm too wide). Its top is a
    lump wider than a blade with nothing over it: soil. What is left of its rim, joined to the
    leaf, stays (at most a quarter of the top here); the leaf stays up to the clod."""
    rng = np.random.default_rng(seed)
    soil = _soil(rng)
    base = (rng.uniform(-0.3, 0.0), rng.uniform(-0.3, 0.3))
    plant, _ = _plant(base)
    top = _clod(soil, (base[0] + 0.27, base[1]), 0.09, 0.03)
    resting = plant[:, 0] > base[0] + 0.22  # the leaf's last 3 cm lie on the clod
    ground = _ground(plant[resting, 0], plant[resting, 1])
    plant[resting, 2] = np.maximum(plant[resting, 2], ground + 0.034)
    points = np.concatenate([soil, plant])
    sample = points[::4]
    is_plant, _, _ = plants_above_local_ground(points, sample, soil_band_m=0.15)
    assert top.sum() > 100
    assert is_plant[: len(soil)][top].mean() < 0.25
    assert is_plant[len(soil) :][~resting].mean() > 0.97
    monkeypatch.setattr(
        geometry_split, "clod_tops", lambda points, height, plant: np.zeros(len(points), bool)
    )
    joined, _, _ = plants_above_local_ground(points, sample, soil_band_m=0.15)
    assert joined[: len(soil)][top].all()  # without the rule: the whole top is plant


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_low_leaf_under_another_and_the_stem_s_foot_are_no_clod(seed) -> None:
    """A leaf 7 cm wide lying 3 cm over the soil under a higher leaf stays the plant's, as does
    the stem's foot: something grows over them. (A blade that wide, or as wide as the disc
    where cells cut it, lying that low with nothing over it is taken for a clod: the price.)"""
    rng = np.random.default_rng(seed)
    soil = _soil(rng)
    bx, by = rng.uniform(-0.3, 0.0), rng.uniform(-0.3, 0.3)
    g0 = _ground(np.array([bx]), np.array([by]))[0]
    stem = np.column_stack([np.full(300, bx), np.full(300, by), g0 + np.linspace(0.0, 0.25, 300)])
    along, across = np.meshgrid(np.arange(0.01, 0.2, 0.004), np.arange(-0.035, 0.036, 0.004))
    x, y = bx - along.ravel(), by + across.ravel()
    under = np.column_stack([x, y, _ground(x, y) + 0.03])
    over = np.column_stack([x, y, _ground(x, y) + 0.12])
    plant = np.concatenate([stem, under, over])
    points = np.concatenate([soil, plant])
    is_plant, _, _ = plants_above_local_ground(points, points[::4], soil_band_m=0.15)
    on_plant = is_plant[len(soil) :]
    assert on_plant[len(stem) : len(stem) + len(under)].mean() > 0.97
    assert on_plant[: len(stem)][stem[:, 2] - g0 > 0.015].all()  # the stem's foot


@pytest.mark.slow
def test_a_depth_only_plot_with_clods_finds_its_plants_and_no_clod(tmp_path: Path) -> None:
    session = tmp_path / "cloddy"
    options = ["--seed", "1", "--grid", "2", "--clods", "25", "--depth-only"]
    assert main(["simulate", "--out", str(session), *options]) == 0
    result = run_reconstruction(load_session(session), ReconstructionSettings())
    truth = json.loads((session / "truth.json").read_text())
    errors = matched_errors(result, truth)
    assert len(result.plants) == len(truth["plants"]) == 4  # 91 with the bar at 3 cm
    assert np.sqrt(np.mean(errors["dh_cm"] ** 2)) <= 1.0  # measured 0.42
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 1.5  # measured 1.03


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_coarse_seedbed_s_clods_under_low_leaves_do_not_widen_the_plants(tmp_path: Path) -> None:
    """Clods up to 14 cm across among seedlings with narrow blades, depth-only (``simulate
    --clods 30 --clod-size 14 --leaf-width 0.5 --depth-only``, seed 1): a clod that a low leaf
    rests on made one plant 20.7 cm too wide, width RMSE 5.41 cm; measured with the clods' tops
    told from the leaves 1.48 cm, the worst plant 3.0 cm out."""
    session = tmp_path / "coarse"
    options = ["--seed", "1", "--clods", "30", "--clod-size", "14", "--leaf-width", "0.5"]
    assert main(["simulate", "--out", str(session), *options, "--depth-only"]) == 0
    result = run_reconstruction(load_session(session), ReconstructionSettings())
    truth = json.loads((session / "truth.json").read_text())
    assert truth["clod_size_cm"] == 14
    errors = matched_errors(result, truth)
    assert len(result.plants) == len(truth["plants"]) == 16
    assert np.sqrt(np.mean(errors["dh_cm"] ** 2)) <= 1.0  # measured 0.42
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 2.0  # measured 1.48 (5.41 before)
    assert np.abs(errors["dw_cm"]).max() <= 5.0  # measured 3.0 (20.7 before)
    # without colour every pixel between two surfaces is flagged: it holds its plant together
    # but its width is the enclosing circle of the other points
    flagged = 0
    for plant in result.plants:
        assert plant.cloud.mixed is not None
        flagged += int(plant.cloud.mixed.sum())
        unflagged = plant.cloud.points[~plant.cloud.mixed, :2].astype(np.float32)
        assert 200 * cv2.minEnclosingCircle(unflagged)[1] == pytest.approx(
            100 * plant.traits.width_m, abs=0.05
        )
    assert flagged > 100


@pytest.mark.slow
def test_a_clod_cut_from_the_leaf_it_touched_is_no_plant(tmp_path: Path) -> None:
    """The geometry split keeps a clod that a low leaf touches; the plants step cut one from
    its leaf on this plot (40 clods a square metre) and counted it: a 3.9 cm "plant" of 404
    points, off the planting grid. Without colour a plant must reach the split's bar."""
    session = tmp_path / "clods"
    options = ["--seed", "1", "--clods", "40", "--depth-only"]
    assert main(["simulate", "--out", str(session), *options]) == 0
    result = run_reconstruction(load_session(session), ReconstructionSettings())
    truth = json.loads((session / "truth.json").read_text())
    errors = matched_errors(result, truth)
    assert len(result.plants) == len(truth["plants"]) == 16  # 17 before
    assert min(p.traits.height_m for p in result.plants) >= 0.08
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 1.5  # measured 0.87


def test_only_a_plot_told_by_geometry_alone_raises_the_plants_height_bar() -> None:
    plants, filters = PlantSettings(), FilterSettings()
    by = [SimpleNamespace(separation=SimpleNamespace(by_geometry=g)) for g in (True, True)]
    mixed = [*by, SimpleNamespace(separation=SimpleNamespace(by_geometry=False))]
    assert stages.plant_settings(plants, filters, by).min_height_m == 0.08  # type: ignore[arg-type]
    assert stages.plant_settings(plants, filters, mixed) is plants  # type: ignore[arg-type]
    assert stages.plant_settings(plants, filters, []) is plants


def test_soil_a_low_leaf_lifts_at_its_median_stays_soil_at_its_own_depth() -> None:
    """Told apart on the blocks' median depths (in the sun), a soil pixel beside a leaf lying
    low over it has the leaf in its window, and its median stands clear of the ground where
    it does not: it must stand clear at its own depth too, or the plant takes in a halo of
    soil (a sunlit depth-only plot's widths 1.44 cm RMSE, 0.89 with the rule)."""
    rng = np.random.default_rng(4)
    soil = _soil(rng)
    plant, _ = _plant((-0.2, 0.0))
    own = np.concatenate([soil, plant])
    median = own.copy()
    beside = np.flatnonzero(  # the soil along the leaf's lower half, lifted by its window
        (np.abs(soil[:, 1]) < 0.02) & (soil[:, 0] > -0.05) & (soil[:, 0] < 0.05)
    )
    median[beside, 2] += 0.015
    sample = median[::4]
    lifted, _, _ = plants_above_local_ground(median, sample, soil_band_m=0.15)
    assert lifted[beside].mean() > 0.9  # the halo, judged on the medians alone
    is_plant, _, _ = plants_above_local_ground(median, sample, 0.15, own)
    assert is_plant[beside].mean() < 0.01  # what the relief and noise lift anyway
    assert is_plant[len(soil) :].mean() > 0.95


def test_filter_station_by_geometry_keeps_the_soil_sample_free_of_plant() -> None:
    rng = np.random.default_rng(3)
    soil = _soil(rng)
    plant, _ = _plant((0.0, 0.0))
    points = np.concatenate([soil, plant])
    grey = np.full((len(points), 3), 128, np.uint8)
    sample = Cloud(points[::4], grey[::4])
    result = filter_station(
        Cloud(points, grey), sample, FilterSettings(), 0.15, 0.02, by_geometry=True
    )
    assert result.kept["geometry"] >= 0.95 * len(plant)
    assert result.soil_m[:, 2].max() < 0.06  # soil only: the stem's 25 cm are not in it
    assert len(result.plants) > 100


def _depth_only_copy(session: Path, out: Path, color: str | None = None) -> Path:
    """``session`` rewritten as depth-only (``color`` None) or with every capture's colour
    replaced by the one image ``color`` names (copied into ``out``)."""
    shutil.copytree(session, out, ignore=shutil.ignore_patterns("color.png", "ir.png"))
    document = json.loads((session / "session.json").read_text())
    for capture in document["captures"]:
        capture.pop("color")
        capture.pop("ir", None)
        for name in ("color", "ir"):  # the files are gone: so are their recorded checksums
            capture.get("sha256", {}).pop(name, None)
        if color is not None:
            capture["color"] = color
    (out / "session.json").write_text(json.dumps(document))
    return out


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_depth_only_plot_finds_every_plant_within_the_targets(
    plot_session: Simulated, tmp_path: Path
) -> None:
    folder = _depth_only_copy(plot_session.folder, tmp_path / "depth-only")
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    assert set(result.separation.values()) == {"plants separated by geometry: no colour"}
    errors = matched_errors(result, plot_session.truth)
    assert len(result.plants) == len(plot_session.truth["plants"])
    assert np.sqrt(np.mean(errors["dh_cm"] ** 2)) <= 1.0
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 1.5
    assert result.report()["plant_separation"]["5"] == "plants separated by geometry: no colour"


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_a_second_seed_simulated_depth_only_is_within_the_targets(tmp_path: Path) -> None:
    folder = tmp_path / "seed3"
    assert main(["simulate", "--out", str(folder), "--seed", "3", "--depth-only"]) == 0
    truth = json.loads((folder / "truth.json").read_text())
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    errors = matched_errors(result, truth)
    assert len(result.plants) == len(truth["plants"])
    assert np.sqrt(np.mean(errors["dh_cm"] ** 2)) <= 1.0
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 1.5


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_grey_colour_image_is_not_a_silent_no_plant(
    plot_session: Simulated, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _depth_only_copy(plot_session.folder, tmp_path / "grey", color="grey.png")
    cv2.imwrite(str(folder / "grey.png"), np.full((424, 512, 3), 128, np.uint8))
    document = json.loads((folder / "session.json").read_text())
    document["captures"] = [c for c in document["captures"] if c["station"] in (4, 5, 6)]
    (folder / "session.json").write_text(json.dumps(document))
    capsys.readouterr()
    assert main(["reconstruct", str(folder), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert (
        "plants separated by geometry: colour has no green contrast (stations 4, 5, 6)" in printed
    )
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert set(report["plant_separation"].values()) == {
        "plants separated by geometry: colour has no green contrast"
    }
    assert report["exg_thresholds"] == {}
    assert report["plants"] >= 8  # the middle row of stations sees at least half the plot
    assert "no plant found" not in report["warnings"]
