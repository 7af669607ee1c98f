"""A leaf's surface followed past its green (``scans.continued_surfaces``): the last
centimetres of a tip whose colour mixes with the soil's, or yellows, continue the leaf's depth
and stand above the ground; the soil does neither. Such points are kept apart from the plants
(``filters.filter_station``) and join them only after the plants are found (``stages.fuse``
hands them to the plants step with the doubtful points)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from devices.camera.frames import KINECT_V2_PAPER as K
from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.filters import filter_station
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.scans import (
    CONTINUED_MIN_HEIGHT_M,
    CONTINUED_REACH_PX,
    MIN_GROUND_PIXELS,
    DepthEdges,
    continued_surfaces,
    frame_ground_heights,
)
from fieldapp.recon.settings import FilterSettings, ReconstructionSettings

from .test_end_to_end import matched_errors

CAMERA_HEIGHT_M = 2.0


def _rays() -> NDArray[np.float64]:
    v, u = np.mgrid[0 : K.height, 0 : K.width].astype(np.float64)
    return np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones_like(u)], axis=2)


def _soil_pixels(shape: tuple[int, int], mask: NDArray[np.bool_]) -> NDArray[np.intp]:
    grid = np.zeros(shape, bool)
    grid[::4, ::4] = True
    return np.flatnonzero(grid & ~mask)


def _looking_down(
    leaf_depth_m: NDArray[np.float64] | float, leaf: NDArray[np.bool_]
) -> NDArray[np.float32]:
    """A camera looking straight down from 2 m on flat soil, a leaf in ``leaf`` at its depth."""
    depth = np.full((K.height, K.width), CAMERA_HEIGHT_M, np.float32)
    depth[leaf] = np.broadcast_to(leaf_depth_m, depth.shape)[leaf]
    return depth


TAN, SOIL, GREY = (183, 158, 131), (149, 121, 93), (200, 200, 196)


def _colours(leaf: NDArray[np.bool_], grey: NDArray[np.bool_] | None = None) -> NDArray[np.uint8]:
    """The frame's colours (H * W, 3): the soil's brown, the leaf (tip) tan, ``grey`` grey."""
    colours = np.empty((*leaf.shape, 3), np.uint8)
    colours[:] = SOIL
    colours[leaf] = TAN
    if grey is not None:
        colours[grey] = GREY
    return colours.reshape(-1, 3)


def _strip(columns: slice) -> NDArray[np.bool_]:
    mask = np.zeros((K.height, K.width), bool)
    mask[200:212, columns] = True
    return mask


def test_a_tip_whose_colour_is_not_green_is_followed_to_its_end_and_no_further() -> None:
    leaf = _strip(slice(150, 260))
    green = _strip(slice(150, 250))  # the last 10 pixels (about 4 cm at 1.6 m) are not green
    depth = _looking_down(1.6, leaf)
    edges = DepthEdges.of(depth, np.ones(depth.shape, bool))
    heights = frame_ground_heights(_rays(), depth, _soil_pixels(depth.shape, leaf))
    assert heights is not None
    continued = continued_surfaces(green, edges, heights, _colours(leaf))
    tip = np.flatnonzero((leaf & ~green).reshape(-1))
    np.testing.assert_array_equal(continued, tip)  # every pixel of the tip, the soil's none


def test_a_tip_is_followed_no_farther_than_the_reach() -> None:
    leaf = _strip(slice(150, 300))
    green = _strip(slice(150, 200))
    depth = _looking_down(1.6, leaf)
    edges = DepthEdges.of(depth, np.ones(depth.shape, bool))
    heights = frame_ground_heights(_rays(), depth, _soil_pixels(depth.shape, leaf))
    assert heights is not None
    continued = continued_surfaces(green, edges, heights, _colours(leaf))
    columns = np.unique(np.divmod(continued, K.width)[1])
    np.testing.assert_array_equal(columns, np.arange(200, 200 + CONTINUED_REACH_PX))


def test_a_leaf_coming_down_to_the_soil_is_followed_down_to_its_ground_band_only() -> None:
    # the leaf's outer part slopes from 40 cm above the soil down onto it: its depth runs on
    # into the soil's without an edge, and the soil around its end is never taken
    leaf = _strip(slice(150, 270))
    green = _strip(slice(150, 240))
    columns = np.arange(K.width, dtype=np.float64)
    above_m = np.interp(columns, [150, 240, 262], [0.4, 0.1, 0.0])
    depth = _looking_down((CAMERA_HEIGHT_M - above_m)[None, :] * np.ones((K.height, 1)), leaf)
    edges = DepthEdges.of(depth, np.ones(depth.shape, bool))
    heights = frame_ground_heights(_rays(), depth, _soil_pixels(depth.shape, leaf))
    assert heights is not None
    continued = continued_surfaces(green, edges, heights, _colours(leaf))
    row, column = np.divmod(continued, K.width)
    assert len(continued) > 0 and set(np.unique(row)) <= set(range(200, 212))
    reached_m = above_m[column]
    assert reached_m.min() > CONTINUED_MIN_HEIGHT_M - 0.01
    assert column.max() < 262  # stopped before the leaf lies on the soil


def test_a_grey_sphere_a_tip_touches_and_a_pixel_without_colour_are_not_followed() -> None:
    # the tip runs on into a white sphere's side at its own depth, and past a black pixel
    leaf = _strip(slice(150, 240))
    sphere = _strip(slice(240, 262))
    green = _strip(slice(150, 230))
    depth = _looking_down(1.6, leaf | sphere)
    edges = DepthEdges.of(depth, np.ones(depth.shape, bool))
    heights = frame_ground_heights(_rays(), depth, _soil_pixels(depth.shape, leaf | sphere))
    assert heights is not None
    continued = continued_surfaces(green, edges, heights, _colours(leaf, sphere))
    np.testing.assert_array_equal(continued, np.flatnonzero((leaf & ~green).reshape(-1)))
    colours = _colours(leaf)
    colours.reshape(K.height, K.width, 3)[200:212, 235] = 0  # black across the tip
    continued = continued_surfaces(green, edges, heights, colours)
    assert np.divmod(continued, K.width)[1].max() == 234


def test_the_frame_ground_is_a_plane_through_the_soil_below_a_tilted_camera() -> None:
    # soil seen from 1.5 m up by a camera pitched 35 degrees down, a 30 cm box standing on it
    rays = _rays()
    pitch = np.radians(35.0)
    down = np.array([0.0, np.cos(pitch), np.sin(pitch)])  # the world's down in the camera
    t = 1.5 / np.clip(rays @ down, 1e-3, None)  # each ray's depth (z) to the soil
    depth = np.minimum(t, 6.0).astype(np.float32)
    box = np.zeros(depth.shape, bool)
    box[260:300, 200:260] = True
    depth[box] *= 1 - 0.3 / 1.5  # 30 cm nearer along the ray: the box's top is 30 cm up
    heights = frame_ground_heights(rays, depth, _soil_pixels(depth.shape, box | (t > 6.0)))
    assert heights is not None
    soil = np.flatnonzero((~box & (t < 6.0)).reshape(-1))[::97]
    np.testing.assert_allclose(heights(soil), 0.0, atol=1e-6)
    top = np.flatnonzero(box.reshape(-1))
    np.testing.assert_allclose(heights(top), 0.3, atol=1e-6)


def test_a_frame_with_too_little_soil_has_no_ground() -> None:
    depth = np.full((K.height, K.width), 1.5, np.float32)
    assert frame_ground_heights(_rays(), depth, np.arange(MIN_GROUND_PIXELS - 1)) is None


def _cloud(points: list[list[float]]) -> Cloud:
    array = np.asarray(points, dtype=np.float64)
    return Cloud(array, np.full((len(array), 3), (120, 100, 70), np.uint8))


def test_continued_points_are_kept_apart_from_the_plants_and_only_clear_of_the_ground() -> None:
    settings = FilterSettings()
    xs = np.linspace(-0.5, 0.5, 21)
    soil = _cloud([[x, y, 0.0] for x in xs for y in xs])
    green = Cloud(np.array([[0.0, 0.0, 0.3]]), np.array([[40, 140, 30]], np.uint8))
    low, high = (
        settings.pass_through_continued_min_m - 0.01,
        settings.pass_through_continued_min_m + 0.01,
    )
    continued = _cloud(
        [[0.2, 0.0, low], [0.3, 0.0, high], [0.3, 0.1, 1.6 * settings.pass_through_max_m]]
    )
    station = filter_station(green, soil, settings, 0.05, 0.01, continued=continued)
    assert len(station.plants) == 1  # the green point alone
    np.testing.assert_allclose(station.continued.points, [[0.3, 0.0, high]])
    assert station.kept["continued"] == 1
    without = filter_station(green, soil, settings, 0.05, 0.01)
    assert len(without.continued) == 0 and "continued" not in without.kept


def test_without_colour_nothing_is_continued() -> None:
    settings = FilterSettings()
    xs = np.linspace(-0.5, 0.5, 21)
    soil = _cloud([[x, y, 0.0] for x in xs for y in xs])
    continued = _cloud([[0.3, 0.0, 0.3]])
    station = filter_station(soil, soil, settings, 0.05, 0.01, True, continued=continued)
    assert len(station.continued) == 0


def _dry_plot(
    folder: Path, options: list[str]
) -> tuple[dict[str, int], dict[str, NDArray[np.float64]]]:
    assert main(["simulate", "--out", str(folder), *options]) == 0
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    truth = json.loads((folder / "truth.json").read_text())
    assert len(result.plants) == len(truth["plants"]) == 16
    return dict(result.kept), matched_errors(result, truth)


@pytest.mark.slow
def test_seedlings_with_dry_tips_measure_as_green_ones(tmp_path: Path) -> None:
    """``simulate --dry-tips 3`` (seed 1): every leaf's last 3 cm the soil's colour. Without
    the surfaces continued past the green, height RMSE 0.75 cm and width RMSE 0.99 cm (the
    green plot: 0.38 / 0.68); measured with them 0.42 / 0.78."""
    kept, errors = _dry_plot(tmp_path / "dry", ["--seed", "1", "--dry-tips", "3"])
    assert kept["continued"] > 100
    assert np.sqrt(np.mean(errors["dh_cm"] ** 2)) <= 0.55
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 0.9


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_touching_plants_with_dry_tips_keep_their_tops_and_their_widths(tmp_path: Path) -> None:
    """``simulate --stage touching --dry-tips 6`` (seed 3): the top leaf's dry tip is the
    plant's top. Without the surfaces continued past the green, height RMSE 2.32 cm and width
    RMSE 3.97 cm (the green plot: 0.39 / 1.16); measured with them 0.57 / 1.35."""
    options = ["--seed", "3", "--stage", "touching", "--dry-tips", "6"]
    _, errors = _dry_plot(tmp_path / "dry", options)
    assert np.sqrt(np.mean(errors["dh_cm"] ** 2)) <= 1.0
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 2.0
