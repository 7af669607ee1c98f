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
from fieldapp.recon import stages
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
