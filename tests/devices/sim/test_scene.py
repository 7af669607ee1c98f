"""Plants, soil, spheres and boards: seeded, growing, and their truth computed from the mesh."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from devices.geometry import transform_points
from devices.sim.boards import Checkerboard, PlacedBoard, board_facing, board_lying
from devices.sim.plants import MAX_LEAVES, leaves_on_day, make_plant
from devices.sim.scene import (
    SPHERE_DIAMETERS_MM,
    PlotLayout,
    empty_scene,
    plot_scene,
    spheres_scene,
)
from devices.sim.soil import Soil, SoilSpec


def test_same_seed_same_plant_and_it_grows_with_the_days() -> None:
    a = make_plant(7, 0, (0.0, 0.0), 0.0)
    b = make_plant(7, 0, (0.0, 0.0), 0.0)
    np.testing.assert_array_equal(a.vertices_m, b.vertices_m)
    later = make_plant(7, 10, (0.0, 0.0), 0.0)
    assert later.height_m == pytest.approx(a.height_m * 1.5, rel=1e-6)
    assert len(later.vertices_m) > len(a.vertices_m)  # new leaves
    assert not np.array_equal(make_plant(8, 0, (0.0, 0.0), 0.0).vertices_m[:50], a.vertices_m[:50])


def test_leaf_count_grows_every_five_days_up_to_nine() -> None:
    assert [leaves_on_day(5, d) for d in (0, 4, 5, 10, 40)] == [5, 5, 6, 7, MAX_LEAVES]


def test_plant_truth_is_computed_from_its_mesh() -> None:
    plant = make_plant(3, 0, (0.5, -0.2), 0.01)
    assert plant.height_m == pytest.approx(plant.vertices_m[:, 2].max() - 0.01)
    assert 0.24 < plant.height_m < 0.36  # about 30 cm on day 0
    xy = plant.vertices_m[:, :2]
    # the smallest enclosing circle is at least as wide as the widest pair of points and at
    # most as wide as the circle around the bounding box
    widest = max(np.linalg.norm(p - q) for p, q in itertools.combinations(xy[::5], 2))
    assert widest - 1e-6 <= plant.width_m <= np.hypot(*np.ptp(xy, axis=0)) + 1e-6
    assert plant.base_m == pytest.approx([0.5, -0.2, 0.01])


def test_plot_layout_and_truth() -> None:
    scene = plot_scene(seed=4, day=0)
    assert len(scene.plants) == 16
    xy = np.array([[p.x_m, p.y_m] for p in scene.plants])
    grid = np.array([[x, y] for y in (-1.2, -0.4, 0.4, 1.2) for x in (-1.2, -0.4, 0.4, 1.2)])
    assert np.abs(xy - grid).max() <= PlotLayout().jitter_m + 1e-9
    for plant, body in zip(scene.plants, scene.bodies[1:], strict=True):
        assert plant.z_m == pytest.approx(scene.soil.height_at(plant.x_m, plant.y_m))  # type: ignore[union-attr]
        assert plant.height_cm == pytest.approx(100 * (body.vertices_m[:, 2].max() - plant.z_m))
        assert 20 < plant.height_cm < 40 and 20 < plant.width_cm < 80
    later = plot_scene(seed=4, day=10)
    assert [p.x_m for p in later.plants] == [p.x_m for p in scene.plants]
    assert all(b.height_cm > a.height_cm for a, b in zip(scene.plants, later.plants, strict=True))


def test_soil_has_a_few_cm_of_relief_around_a_zero_mean() -> None:
    soil = Soil(SoilSpec(), seed=2)
    vertices, triangles = soil.mesh()
    plot = np.abs(vertices[:, :2]).max(axis=1) < 3.0
    z = vertices[plot, 2]
    assert abs(vertices[:, 2].mean()) < 1e-3
    assert 0.01 < np.ptp(z) < 0.15 and 0.005 < z.std() < 0.04
    assert triangles.max() < len(vertices)
    rgb, ir = soil.albedo(vertices[:1000])
    assert rgb.shape == (1000, 3) and (rgb[:, 0] > rgb[:, 2]).all()  # brown
    assert ir.std() > 0.0  # textured


def test_spheres_rest_on_the_soil() -> None:
    scene = spheres_scene(seed=1)
    assert sorted(s.diameter_mm for s in scene.spheres) == sorted(SPHERE_DIAMETERS_MM)
    assert scene.soil is not None
    for sphere, body in zip(scene.spheres, scene.bodies[1:], strict=True):
        radius = sphere.diameter_mm / 2000
        assert sphere.z_m - radius == pytest.approx(scene.soil.height_at(sphere.x_m, sphere.y_m))
        distance = np.linalg.norm(body.vertices_m - [sphere.x_m, sphere.y_m, sphere.z_m], axis=1)
        assert distance == pytest.approx(radius, rel=1e-6)
    assert not spheres_scene(seed=1).plants and len(spheres_scene(1, with_plants=True).plants) == 16


def test_board_geometry_and_placement() -> None:
    board = Checkerboard("b", inner_cols=9, inner_rows=6, square_m=0.04)
    assert board.object_points_m.shape == (54, 3)
    assert board.object_points_m[1] == pytest.approx([0.04, 0, 0])  # row by row, x first
    centre, eye = np.array([1.0, 2.0, 0.5]), np.array([0.0, 0.0, 1.3])
    T = board_facing(board, centre, eye, roll_deg=10.0)
    assert transform_points(T, board.centre_m[None])[0] == pytest.approx(centre)
    towards_board = (centre - eye) / np.linalg.norm(centre - eye)
    assert T[:3, 2] == pytest.approx(towards_board)  # z into the board, printed face to the eye
    lying = board_lying(board, centre, yaw_deg=30.0)
    assert lying[:3, 2] == pytest.approx([0, 0, -1])  # face up
    corners = PlacedBoard(board, lying).corners_field_m
    assert corners[:, 2] == pytest.approx(0.5)
    black = board.is_black(np.array([[-0.02, -0.02], [0.02, -0.02], [0.5, 0.5]]))
    assert black.tolist() == [True, False, False]  # the outer square row, then the white margin
    with pytest.raises(ValueError, match="inner corners"):
        Checkerboard("bad", inner_cols=1)


def test_a_plot_needs_soil() -> None:
    from devices.sim.scene import Scene, add_plot

    with pytest.raises(ValueError, match="soil"):
        add_plot(Scene(soil=None), 0, 0, PlotLayout())
    assert empty_scene(0).bodies[0].kind == "soil"
