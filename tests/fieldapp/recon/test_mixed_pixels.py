"""Mixed pixels: a time-of-flight pixel across a depth edge returns a depth between the two
surfaces it sees, a point in the air off every surface. Where such a pixel has no colour of its
own (libfreenect2's black beside a near edge) and is kept as plant, its point holds the plant
together but does not set its width (``scans.mixed_pixels``, ``Cloud.mixed``,
``cloud.width_points``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from devices.camera.frames import KINECT_V2_PAPER as K
from devices.geometry import make_transform
from devices.sim.render import SensorModel
from devices.sim.sensor import veiled
from fieldapp.cli import main
from fieldapp.io.session import Capture, CaptureImages, load_session
from fieldapp.recon.backproject import backproject_pixels_twice, ray_table
from fieldapp.recon.cloud import Cloud, joined_mixed, width_points
from fieldapp.recon.filters import voxel_mean
from fieldapp.recon.outputs import PointLabels, ply_bytes, read_labelled_ply, read_ply
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.plants import Plant, find_plants, widest_meets
from fieldapp.recon.scans import (
    CONTINUOUS_SHARE,
    DepthEdges,
    _green_and_soil,
    _green_keys,
    _separation,
    frame_of,
    mixed_pixels,
)
from fieldapp.recon.settings import CropSettings, PlantSettings, ReconstructionSettings
from fieldapp.recon.station import station_cloud
from fieldapp.recon.traits import measure_plant
from fieldapp.results.correction_plot import PlotState, measure_again

from .synthetic import LEAF_RGB, SOIL_RGB, seedling
from .test_end_to_end import matched_errors

SOIL_M, LOWER_M, UPPER_M = 1.6, 1.0, 0.7


def _edges(depth: NDArray[np.float32]) -> DepthEdges:
    return DepthEdges.of(depth, np.isfinite(depth))


def _row(depth: NDArray[np.float32], row: int, columns: range) -> NDArray[np.bool_]:
    """Which pixels of ``row`` over ``columns`` :func:`mixed_pixels` finds mixed."""
    pixels = np.array([row * depth.shape[1] + c for c in columns], dtype=np.intp)
    return mixed_pixels(_edges(depth), pixels)


def test_a_pixel_between_a_leaf_and_the_soil_is_mixed_and_the_leaf_s_edge_is_not() -> None:
    depth = np.full((40, 60), SOIL_M, np.float32)
    depth[10:30, 10:30] = LOWER_M  # a leaf, 60 cm above the soil along the ray
    depth[10:30, 30] = 1.3  # its right edge's mixed pixels, half way
    depth[10:30, 31] = 1.45  # and a second row of them, deeper still
    mixed = _row(depth, 20, range(26, 36))
    # columns 26-29 the leaf (29 its own edge: the leaf beside it), 30-31 mixed, 32-35 soil
    assert mixed.tolist() == [False] * 4 + [True, True] + [False] * 4


def test_a_stem_against_the_soil_and_a_leaf_seen_face_on_are_not_mixed() -> None:
    depth = np.full((40, 60), SOIL_M, np.float32)
    depth[:, 20] = LOWER_M  # a stem one pixel wide: the soil farther on both sides
    depth[5:35, 35:55] = np.linspace(0.9, 1.1, 20, dtype=np.float32)  # a leaf, sloping
    assert not _row(depth, 20, range(15, 26)).any()
    assert not _row(depth, 20, range(36, 54)).any()


def test_a_veil_of_gentle_steps_is_mixed_and_a_surface_near_grazing_is_not() -> None:
    """A veil five pixels deep between a leaf's edge and a lower leaf 15 cm behind it steps 2.5
    cm a pixel, under :data:`CONTINUOUS_SHARE` of its distance: each of its pixels is still
    between two surfaces. A surface seen 10 degrees from grazing (1.5 % a pixel) is not."""
    depth = np.full((40, 60), SOIL_M, np.float32)
    depth[10:30, 10:30] = LOWER_M
    depth[10:30, 30:35] = np.arange(1, 6, dtype=np.float32) * 0.025 + LOWER_M
    depth[10:30, 35:50] = LOWER_M + 0.15
    assert (np.diff(depth[20, 29:36]) / depth[20, 30:36] < CONTINUOUS_SHARE).all()
    assert _row(depth, 20, range(27, 38)).tolist() == [False] * 3 + [True] * 5 + [False] * 3
    grazing = np.full((40, 60), SOIL_M, np.float32)
    grazing[5:35, 5:55] = (UPPER_M * 1.015 ** np.arange(50)).astype(np.float32)
    assert not _row(grazing, 20, range(6, 54)).any()


def test_a_veil_grown_over_a_leaf_s_rim_is_flagged_though_it_has_the_soil_s_colour() -> None:
    """A veil three pixels deep between a leaf and the soil 10 cm behind it, with the soil's
    colour (the colour camera sees the soil there): its first pixel continues the leaf within
    :data:`CONTINUOUS_SHARE` and is grown over the leaf's rim as plant; it lies between two
    surfaces, so it is flagged and does not widen the leaf (``scans._green_and_soil``)."""
    depth = np.full((K.height, K.width), LOWER_M + 0.1, np.float32)
    leaf = np.zeros(depth.shape, bool)
    leaf[150:260, 150:350] = True
    depth[leaf] = LOWER_M
    depth = veiled(depth, 3, SensorModel().edge_jump)
    color = np.empty((*depth.shape, 3), np.uint8)
    color[:] = SOIL_RGB
    color[leaf] = LEAF_RGB
    frame = frame_of(CaptureImages(Capture(station=1, view=0, depth="d", color="c"), depth, color))
    separation, threshold, weak, rim_px, tally, _ = _separation([frame], "otsu")
    grid = np.arange(0, depth.size, 8, dtype=np.intp)
    keys = _green_keys(threshold, weak, tally)
    green = _green_and_soil(frame, separation, keys, rim_px, grid, ray_table(K), CropSettings())[0]
    veil = (green.points[:, 2] > LOWER_M + 0.005) & (green.points[:, 2] < LOWER_M + 0.095)
    assert veil.sum() > 100  # grown over the rim: the ring's first pixels, all round the leaf
    assert green.mixed is not None
    assert green.mixed[veil].all() and not green.mixed[~veil].any()


@pytest.mark.parametrize("width_px", [2, 3, 6])
def test_a_lower_leaf_between_an_upper_leaf_and_the_soil_is_not_mixed(width_px: int) -> None:
    """Touching canopies: a lower leaf's tip peeks out from under an upper leaf, the soil
    beyond it. It lies between a nearer and a farther surface, but it is a surface: each of its
    pixels continues it on one side."""
    depth = np.full((40, 60), SOIL_M, np.float32)
    depth[5:35, 5:20] = UPPER_M
    depth[5:35, 20 : 20 + width_px] = LOWER_M
    assert not _row(depth, 20, range(20, 20 + width_px)).any()
    depth[5:35, 20] = LOWER_M - 0.1  # the strip one pixel wide left: nothing continues it
    depth[5:35, 21 : 20 + width_px] = SOIL_M
    assert _row(depth, 20, range(20, 21)).all()


def test_unmeasured_neighbours_are_neither_nearer_nor_farther() -> None:
    depth = np.full((20, 20), np.nan, np.float32)
    depth[10, 5:15] = np.linspace(1.0, 1.6, 10, dtype=np.float32)  # steps of 4 %, one row
    assert not _row(depth, 9, range(5, 15)).any()  # a row of nothing measured
    pixels = np.array([0, 19, 380, 399], dtype=np.intp)  # the frame's corners
    assert not mixed_pixels(_edges(depth), pixels).any()


def _cloud(n: int, mixed: list[bool] | None) -> Cloud:
    points = np.arange(3 * n, dtype=np.float64).reshape(n, 3)
    colors = np.zeros((n, 3), np.uint8)
    return Cloud(points, colors, None if mixed is None else np.array(mixed))


def test_the_flags_go_with_their_points_through_selection_moves_and_joins() -> None:
    cloud = _cloud(4, [False, True, True, False])
    assert cloud.select(np.array([1, 3])).mixed.tolist() == [True, False]  # type: ignore[union-attr]
    assert cloud.select(cloud.points[:, 0] > 0).mixed.tolist() == [True, True, False]  # type: ignore[union-attr]
    moved = cloud.transformed(make_transform(np.eye(3), np.array([1.0, 0.0, 0.0])))
    assert moved.mixed is cloud.mixed
    joined = Cloud.concatenate([_cloud(2, None), cloud])
    assert joined.mixed is not None and joined.mixed.tolist() == [False, False, *cloud.mixed]  # type: ignore[misc]
    assert Cloud.concatenate([_cloud(2, None), _cloud(1, None)]).mixed is None
    assert joined_mixed([]) is None
    with pytest.raises(ValueError, match="mixed"):
        Cloud(cloud.points, cloud.colors, np.zeros(3, bool))


def test_a_station_joins_its_views_flags_in_order() -> None:
    views = {1: _cloud(2, [True, False]), 0: _cloud(3, None)}
    joined = station_cloud(views, make_transform(np.eye(3), np.zeros(3)))
    assert joined.mixed is not None and joined.mixed.tolist() == [False] * 3 + [True, False]


def test_a_voxel_is_a_mixed_pixel_only_where_all_its_points_are() -> None:
    points = np.array([[0.001, 0, 0], [0.002, 0, 0], [0.011, 0, 0], [0.012, 0, 0], [0.021, 0, 0]])
    cloud = Cloud(points, np.zeros((5, 3), np.uint8), np.array([True, True, True, False, False]))
    means = voxel_mean(cloud, 0.01)
    assert means.mixed is not None and means.mixed.tolist() == [True, False, False]
    assert voxel_mean(Cloud(points, np.zeros((5, 3), np.uint8)), 0.01).mixed is None


def test_both_depths_of_a_pixel_keep_its_flag_where_the_crop_drops_others() -> None:
    rays = ray_table(K)
    index = np.array([0, 1000, 2000, 3000], dtype=np.intp)
    depth = np.array([1.0, 9.0, 1.2, 1.4], np.float32)  # the second beyond the crop's 5 m
    colors = np.zeros((4, 3), np.uint8)
    mixed = np.array([False, True, True, False])
    own, other = backproject_pixels_twice(index, depth, depth, colors, rays, 5.0, 0.5, mixed)
    assert own.mixed is not None and own.mixed.tolist() == [False, True, False]
    assert other.mixed is not None and other.mixed.tolist() == own.mixed.tolist()


def test_mixed_points_hold_a_plant_but_do_not_widen_it() -> None:
    angles = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    leaf = np.column_stack([0.1 * np.cos(angles), 0.1 * np.sin(angles), np.full(60, 0.3)])
    stem = np.column_stack([np.zeros(30), np.zeros(30), np.linspace(0.0, 0.3, 30)])
    veil = np.array([[0.16, 0.0, 0.26], [0.18, 0.0, 0.24]])  # off the leaf's edge, in the air
    plant = Cloud(
        np.concatenate([leaf, stem, veil]),
        np.zeros((92, 3), np.uint8),
        np.array([False] * 90 + [True, True]),
    )
    soil = np.array([[x, y, 0.0] for x in (-0.2, 0.2) for y in (-0.2, 0.2)])
    traits = measure_plant(plant.points, soil, 0.02, 0.3, 3, 0.02, width_points(plant))
    assert traits.width_m == pytest.approx(0.2, abs=1e-6)
    assert traits.points == 92  # still the plant's points
    everything = measure_plant(plant.points, soil, 0.02, 0.3, 3, 0.02)
    assert everything.width_m > 0.27
    only_mixed = Cloud(veil, np.zeros((2, 3), np.uint8), np.array([True, True]))
    assert len(width_points(only_mixed)) == 2  # never left without a width


def test_the_plant_files_keep_the_flags_and_files_without_them_read_as_before(
    tmp_path: Path,
) -> None:
    flagged = _cloud(3, [True, False, True])
    (tmp_path / "flagged.ply").write_bytes(ply_bytes(flagged))
    back = read_ply(tmp_path / "flagged.ply")
    assert back.mixed is not None and back.mixed.tolist() == [True, False, True]
    none = np.zeros(3, np.uint8)
    labels = PointLabels(np.array([1, 1, 2], np.int32), none, none)
    (tmp_path / "labelled.ply").write_bytes(ply_bytes(flagged, labels))
    cloud, read_labels = read_labelled_ply(tmp_path / "labelled.ply")
    assert cloud.mixed is not None and cloud.mixed.tolist() == [True, False, True]
    assert read_labels is not None and read_labels.plant_id.tolist() == [1, 1, 2]
    plain = _cloud(3, None)
    (tmp_path / "plain.ply").write_bytes(ply_bytes(plain))
    assert b"mixed" not in (tmp_path / "plain.ply").read_bytes()[:400]  # the same file as before
    assert read_ply(tmp_path / "plain.ply").mixed is None


def test_the_plants_step_keeps_a_veil_in_its_plant_and_out_of_its_width() -> None:
    """A seedling whose leaf's edge trails a veil of mixed pixels down and out along the rays
    of a camera above it: the veil stays part of the plant; its width is the leaf's."""
    rng = np.random.default_rng(3)
    leaf = seedling(rng, 0.0, 0.0, 0.30, 0.30, 6000)
    steps = np.linspace(0.004, 0.06, 15)[:, None]  # 4 mm apart, out to 6 cm past the edge
    veil = np.array([0.15, 0.0, 0.18]) + steps * np.array([0.8, 0.0, -0.6])
    points = np.concatenate([leaf, veil])
    colors = np.tile(np.array(LEAF_RGB, np.uint8), (len(points), 1))
    flags = np.concatenate([np.zeros(len(leaf), bool), np.ones(len(veil), bool)])
    (plant,) = find_plants(Cloud(points, colors, flags), np.zeros((0, 3)), PlantSettings(), 0.15)
    assert plant.traits.points == len(points)  # the veil is the plant's
    assert plant.traits.width_m == pytest.approx(0.30, abs=1e-6)
    (unflagged,) = find_plants(Cloud(points, colors), np.zeros((0, 3)), PlantSettings(), 0.15)
    assert unflagged.traits.width_m > 0.33


def test_a_corrected_plant_is_measured_again_without_its_mixed_points() -> None:
    rng = np.random.default_rng(4)
    leaf = seedling(rng, 0.0, 0.0, 0.30, 0.30, 6000)
    veil = np.array([0.15, 0.0, 0.18]) + np.linspace(0.004, 0.06, 15)[:, None] * [0.8, 0, -0.6]
    points = np.concatenate([leaf, veil])
    n = len(points)
    flags = np.concatenate([np.zeros(len(leaf), bool), np.ones(len(veil), bool)])
    cloud = Cloud(points, np.tile(np.array(LEAF_RGB, np.uint8), (n, 1)), flags)
    labels = PointLabels(np.ones(n, np.int32), np.zeros(n, np.uint8), np.zeros(n, np.uint8))
    ground = np.array([[0.0, 0.0, 0.0]])
    state = PlotState(cloud, labels, {}, {}, ground, organs=False, grid=False)
    measure_again(state, 1, ReconstructionSettings())
    assert state.rows[1].width_cm == pytest.approx(30.0, abs=1e-4)
    assert state.rows[1].points == n


def test_a_veil_reaching_a_neighbour_does_not_make_the_plants_meet() -> None:
    """Two seedlings 10 cm apart at their leaves' edges, one trailing a veil of mixed pixels
    across the gap to within 1 cm of the other: neither plant's widest extent meets the
    other, since the veil is in the air (it would, were its points surface)."""
    rng = np.random.default_rng(5)
    steps = np.linspace(0.004, 0.09, 20)[:, None]
    veil = np.array([0.15, 0.0, 0.18]) + steps * np.array([1.0, 0.0, -0.05])
    a_points = np.concatenate([seedling(rng, 0.0, 0.0, 0.30, 0.30, 6000), veil])
    b_points = seedling(rng, 0.40, 0.0, 0.30, 0.30, 6000)
    soil = np.array([[x, y, 0.0] for x in (-0.3, 0.7) for y in (-0.3, 0.3)])

    def plants(flagged: bool) -> list[Plant]:
        found = []
        for number, points in ((1, a_points), (2, b_points)):
            mixed = np.zeros(len(points), bool)
            if number == 1 and flagged:
                mixed[-len(veil) :] = True
            cloud = Cloud(points, np.zeros((len(points), 3), np.uint8), mixed)
            traits = measure_plant(points, soil, 0.02, 0.3, 3, 0.02, width_points(cloud))
            found.append(Plant(number, traits, cloud))
        return found

    assert widest_meets(plants(True), [[1, 2]], 0.025) == {}
    assert widest_meets(plants(False), [[1, 2]], 0.025) == {1: 2, 2: 1}


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_veiled_seedlings_are_found_and_their_veils_keep_out_of_most_widths(
    tmp_path: Path,
) -> None:
    """A seedling plot whose depth edges trail veils three pixels deep and whose colour has
    libfreenect2's black (``simulate --veil 3 --color-holes``): every plant found, heights as
    without a veil, widths within 2.8 cm (2.51 measured; 5.19 before the veils' pixels were
    flagged at 2 % and the borrowed pixels looked at; 0.79 without a veil: the rest of the veil
    is open, RECONSTRUCTION.md, "Veils several pixels deep")."""
    folder = tmp_path / "veiled"
    options = ["--seed", "1", "--color-holes", "--veil", "3"]
    assert main(["simulate", "--out", str(folder), *options]) == 0
    truth = json.loads((folder / "truth.json").read_text())
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    errors = matched_errors(result, truth)
    assert len(result.plants) == len(truth["plants"]) == len(errors["dw_cm"])
    assert np.sqrt(np.mean(errors["dh_cm"] ** 2)) <= 0.8
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 2.8
