"""Plot coordinates: the field frame put onto the base's map from the stations' map poses."""

from __future__ import annotations

import numpy as np
import pytest

from devices.geometry import make_transform, rotation_z, transform_points
from fieldapp.recon.mapframe import fit_T_map_field, map_alignment


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_fit_recovers_the_map_placement_from_station_axes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    T_map_field = make_transform(rotation_z(rng.uniform(-180, 180)), np.r_[rng.normal(0, 2, 2), 0])
    field_xy = rng.uniform(-2, 2, (9, 2))
    map_xy = transform_points(T_map_field, np.c_[field_xy, np.zeros(9)])[:, :2]
    noisy = map_xy + rng.normal(0.0, 0.01, map_xy.shape)  # the base's localisation
    fitted = fit_T_map_field(field_xy, noisy, 0.0, 0.0)
    probe = np.array([[0.3, -0.7, 0.25]])
    error = transform_points(fitted, probe) - transform_points(T_map_field, probe)
    assert np.max(np.abs(error[:, :2])) < 0.02 and abs(error[0, 2]) < 1e-12


def test_one_station_uses_its_yaw_and_view_zero_heading() -> None:
    camera_in_field = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    R = rotation_z(30.0) @ camera_in_field  # looking along field heading 30 deg, level
    T_field_station = make_transform(R, np.array([1.0, 2.0, 1.3]))
    T = map_alignment({5: (4.0, 5.0, 100.0)}, {5: T_field_station}, np.zeros(3))
    assert T is not None
    forward = (T @ T_field_station)[:3, 2]
    assert np.degrees(np.arctan2(forward[1], forward[0])) == pytest.approx(100.0)
    np.testing.assert_allclose((T @ T_field_station)[:3, 3], [4.0, 5.0, 1.3], atol=1e-12)


def test_no_map_pose_no_alignment() -> None:
    assert map_alignment({}, {5: np.eye(4)}, np.zeros(3)) is None
