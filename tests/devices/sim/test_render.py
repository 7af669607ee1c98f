"""The renderer against analytic ground truth: exact depth, Kinect noise, range, IR."""

from __future__ import annotations

import numpy as np
import pytest

from devices.camera.frames import KINECT_V2_PAPER
from devices.geometry import make_transform
from devices.sim.boards import Checkerboard, PlacedBoard, board_facing
from devices.sim.render import (
    MAX_RANGE_M,
    MIN_RANGE_M,
    Renderer,
    SensorModel,
    axial_noise_m,
    ray_table,
)
from devices.sim.rig import RigGeometry
from devices.sim.scene import Scene, empty_scene
from devices.sim.soil import SoilSpec

FLAT = SoilSpec(relief_m=0.0, clod_m=0.0)


@pytest.fixture(scope="module")
def flat_scene() -> Scene:
    return empty_scene(seed=1, soil_spec=FLAT)


@pytest.fixture(scope="module")
def camera_pose() -> np.ndarray:
    rig = RigGeometry()
    return rig.T_field_camera(rig.station_pose(5), 30.0)


def plane_depth_m(T_field_camera: np.ndarray) -> np.ndarray:
    """Exact depth (H, W) of the plane z = 0 seen from ``T_field_camera`` (inf: no hit)."""
    directions = ray_table(KINECT_V2_PAPER).astype(np.float64) @ T_field_camera[:3, :3].T
    with np.errstate(divide="ignore"):
        t = -T_field_camera[2, 3] / directions[:, 2]
    t[t <= 0] = np.inf
    return t.reshape(KINECT_V2_PAPER.height, KINECT_V2_PAPER.width)


@pytest.mark.parametrize("pitch_deg", [45.0, 20.0])
def test_noise_free_depth_is_exact_on_a_plane(flat_scene: Scene, pitch_deg: float) -> None:
    rig = RigGeometry(pitch_deg=pitch_deg)
    camera_pose = rig.T_field_camera(rig.station_pose(5), 30.0)
    frame = Renderer(flat_scene, KINECT_V2_PAPER, SensorModel(noise=False)).render(camera_pose)
    truth = plane_depth_m(camera_pose)
    in_range = (truth >= MIN_RANGE_M) & (truth <= MAX_RANGE_M)
    assert np.isfinite(frame.depth_m[in_range]).all()
    assert np.abs(frame.depth_m[in_range] - truth[in_range]).max() < 2e-4
    assert np.isnan(frame.depth_m[~in_range]).all()
    assert in_range.mean() > 0.3
    if pitch_deg < 30:
        assert (np.isfinite(truth) & ~in_range).any()  # ground beyond 4.5 m gives no return


def test_depth_noise_on_flat_ground_at_1_5_to_2_m(
    flat_scene: Scene, camera_pose: np.ndarray
) -> None:
    frame = Renderer(flat_scene, KINECT_V2_PAPER).render(camera_pose, np.random.default_rng(4))
    truth = plane_depth_m(camera_pose)
    band = (truth >= 1.5) & (truth <= 2.0) & np.isfinite(frame.depth_m)
    assert band.sum() > 10000
    residual = frame.depth_m[band] - truth[band]
    assert 0.001 <= residual.std() <= 0.004
    assert abs(residual.mean()) < 0.0005
    far = (truth >= 3.5) & (truth <= 4.0) & np.isfinite(frame.depth_m)
    assert (frame.depth_m[far] - truth[far]).std() > residual.std()  # noise grows with distance


def test_axial_noise_matches_the_published_figures() -> None:
    assert axial_noise_m(np.array(1.0), np.array(0.0)) == pytest.approx(0.0013, abs=1e-4)
    assert axial_noise_m(np.array(2.25), np.array(0.0)) == pytest.approx(0.0019, abs=1e-4)
    assert axial_noise_m(np.array(2.0), np.radians(np.array(75.0))) == pytest.approx(
        0.009, abs=1.5e-3
    )


def test_same_rng_same_frame_and_noise_changes_with_it(
    flat_scene: Scene, camera_pose: np.ndarray
) -> None:
    renderer = Renderer(flat_scene, KINECT_V2_PAPER)
    a = renderer.render(camera_pose, np.random.default_rng(1))
    b = renderer.render(camera_pose, np.random.default_rng(1))
    c = renderer.render(camera_pose, np.random.default_rng(2))
    np.testing.assert_array_equal(a.depth_m, b.depth_m)
    assert not np.array_equal(np.nan_to_num(a.depth_m), np.nan_to_num(c.depth_m))
    assert a.color.dtype == np.uint8 and a.color.shape == (424, 512, 3)
    assert a.ir is not None and a.ir.dtype == np.uint16


def test_board_squares_are_visible_in_ir_and_flat_in_depth() -> None:
    board = Checkerboard("b", inner_cols=5, inner_rows=4, square_m=0.1)
    scene = Scene(soil=None)
    T = board_facing(board, np.array([0.0, 0.0, 1.5]), np.zeros(3))
    placed = PlacedBoard(board, T)
    scene.add_board(placed)
    frame = Renderer(scene, KINECT_V2_PAPER, SensorModel(noise=False)).render(np.eye(4))
    assert frame.ir is not None
    # the centres of two neighbouring squares: (0.5, 0.5) is black ((0 + 0) even), (1.5, 0.5) white
    centres = np.array([[0.05, 0.05, 0.0], [0.15, 0.05, 0.0]]) @ T[:3, :3].T + T[:3, 3]
    pixels = centres[:, :2] / centres[:, 2:] * [KINECT_V2_PAPER.fx, KINECT_V2_PAPER.fy]
    u, v = np.rint(pixels + np.array([KINECT_V2_PAPER.cx, KINECT_V2_PAPER.cy])).astype(int).T
    black, white = frame.ir[v[0], u[0]], frame.ir[v[1], u[1]]
    assert white > 8 * black
    assert frame.color[v[1], u[1]].mean() > 4 * frame.color[v[0], u[0]].mean()
    assert frame.depth_m[v, u] == pytest.approx(centres[:, 2], abs=1e-3)


def test_out_of_range_is_missing() -> None:
    scene = Scene(soil=None)
    board = Checkerboard("near", square_m=0.05)
    scene.add_board(PlacedBoard(board, make_transform(np.eye(3), np.array([-0.2, -0.12, 0.4]))))
    frame = Renderer(scene, KINECT_V2_PAPER, SensorModel(noise=False)).render(np.eye(4))
    assert np.isnan(frame.depth_m).all()  # 0.4 m is closer than the sensor's 0.5 m


def test_shadow_map_misses_no_shadow() -> None:
    """Shadow rays cast only where the map allows give the same image as casting them all."""
    from devices.sim.scene import plot_scene

    scene = plot_scene(seed=2)
    scene.add_sphere("ball", 0.0, -0.8, 400)
    board = Checkerboard("standing", square_m=0.06)
    centre = np.array([0.5, -0.6, 0.5])
    scene.add_board(PlacedBoard(board, board_facing(board, centre, np.array([0.0, -1.6, 1.3]))))
    rig = RigGeometry()
    T = rig.T_field_camera(rig.station_pose(2), 90.0, scene.soil)
    mapped = Renderer(scene, KINECT_V2_PAPER, SensorModel(noise=False))
    brute = Renderer(scene, KINECT_V2_PAPER, SensorModel(noise=False))
    brute._shadow_map._mapped = False
    a, b = mapped.render(T).color, brute.render(T).color
    dark = SensorModel(noise=False, shadows=False)
    unshadowed = Renderer(scene, KINECT_V2_PAPER, dark).render(T).color
    shadowed = (unshadowed.astype(int).sum(axis=2) - a.astype(int).sum(axis=2)) > 30
    assert shadowed.mean() > 0.01  # there are shadows in view (plants, the sphere, the board)
    np.testing.assert_array_equal(a, b)
