import numpy as np
import pytest

from devices.geometry import make_transform, rotation_x, rotation_y, transform_points
from fieldapp.recon.ground import (
    GroundNotFound,
    T_field_camera_from_plane,
    T_level,
    fit_ground_plane,
    level_station,
)

from .synthetic import cylinder, ground_patch


def test_a_dense_canopy_layer_above_the_soil_is_not_taken_for_the_ground() -> None:
    rng = np.random.default_rng(1)
    soil = ground_patch(rng, 1.5, 20_000)
    canopy = ground_patch(rng, 0.9, 25_000) + np.array([0.0, 0.0, 0.3])  # more points than the soil
    plane = fit_ground_plane(np.concatenate([soil, canopy]), 0.01, 200, np.array([0, 0, 1.0]))
    np.testing.assert_allclose(plane.normal, [0, 0, 1], atol=2e-3)
    assert abs(plane.offset_m) < 2e-3


def test_tilted_ground_is_levelled_to_z_zero() -> None:
    rng = np.random.default_rng(2)
    T_true = make_transform(rotation_x(3.0) @ rotation_y(-2.0), np.array([0.1, -0.2, 0.04]))
    points = transform_points(
        T_true,
        np.concatenate([ground_patch(rng, 2.0, 30_000), cylinder(rng, 0.3, 0.2, 0.05, 0.4, 3000)]),
    )
    T_correction, plane = level_station(points, 0.01, 200, search_band_m=0.15, max_tilt_deg=10.0)
    levelled = transform_points(T_correction, points)
    soil = levelled[:30_000]
    assert np.abs(soil[:, 2]).max() < 0.006
    assert plane.inlier_fraction > 0.8


def test_no_level_plane_raises() -> None:
    rng = np.random.default_rng(3)
    wall = ground_patch(rng, 1.0, 2000)[:, [2, 0, 1]]  # the plane x = 0
    with pytest.raises(GroundNotFound, match="degrees"):
        fit_ground_plane(wall, 0.01, 100, np.array([0, 0, 1.0]), max_tilt_deg=20.0)


def test_level_transform_maps_the_plane_to_z_zero() -> None:
    rng = np.random.default_rng(4)
    T_true = make_transform(rotation_x(20.0), np.array([0.0, 0.0, -0.5]))
    points = transform_points(T_true, ground_patch(rng, 1.0, 5000, noise_m=0.0))
    plane = fit_ground_plane(points, 0.005, 100, np.array([0, 0, 1.0]), max_tilt_deg=30.0)
    np.testing.assert_allclose(transform_points(T_level(plane), points)[:, 2], 0.0, atol=1e-9)


def test_field_frame_from_a_camera_looking_down() -> None:
    # camera 1.3 m above the ground, pitched 45 degrees down (OpenCV axes)
    rng = np.random.default_rng(5)
    R_field_camera = rotation_x(-135.0)  # camera z forward and down, y down
    T_field_camera = make_transform(R_field_camera, np.array([0.0, 0.0, 1.3]))
    ground_field = ground_patch(rng, 2.0, 5000, noise_m=0.0) + np.array([2.0, 0.0, 0.0])
    ground_camera = transform_points(np.linalg.inv(T_field_camera), ground_field)
    plane = fit_ground_plane(ground_camera, 0.005, 100, np.array([0, -1.0, 0]), max_tilt_deg=80.0)
    T = T_field_camera_from_plane(plane)
    found = transform_points(T, ground_camera)
    np.testing.assert_allclose(found[:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(T[:3, 3], [0.0, 0.0, 1.3], atol=1e-9)
    forward_field = T[:3, :3] @ np.array([0, 0, 1.0])
    assert forward_field[0] > 0.5 and abs(forward_field[1]) < 1e-9
