"""Rigid transform helpers."""

from __future__ import annotations

import numpy as np
import pytest

from devices.geometry import (
    invert,
    make_transform,
    pose_error,
    rigidity_problem,
    rotation_angle_deg,
    rotation_x,
    rotation_y,
    rotation_z,
    transform_points,
)


def test_rotations_are_right_handed():
    np.testing.assert_allclose(rotation_z(90) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(rotation_x(90) @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(rotation_y(90) @ [0, 0, 1], [1, 0, 0], atol=1e-12)


def test_invert_and_transform_points():
    T = make_transform(rotation_z(30) @ rotation_x(-40), np.array([1.0, -2.0, 0.5]))
    points = np.random.default_rng(0).normal(size=(10, 3))
    np.testing.assert_allclose(transform_points(invert(T), transform_points(T, points)), points)
    np.testing.assert_allclose(invert(T) @ T, np.eye(4), atol=1e-12)


@pytest.mark.parametrize(
    ("matrix", "message"),
    [
        (np.eye(3), "4 x 4"),
        (np.diag([1.0, 1.0, -1.0, 1.0]), "determinant"),
        (np.diag([1.0, 1.01, 1.0, 1.0]), "orthonormal"),
        (np.where(np.eye(4) == 1, np.nan, 0.0), "NaN"),
    ],
)
def test_rigidity_problems(matrix, message):
    problem = rigidity_problem(matrix)
    assert problem is not None and message in problem


def test_a_rigid_transform_has_no_problem():
    assert rigidity_problem(make_transform(rotation_y(12.5), np.array([3.0, 0, 0]))) is None


def test_pose_error():
    truth = make_transform(rotation_z(10), np.array([1.0, 2.0, 0.0]))
    estimate = truth @ make_transform(rotation_x(0.5), np.array([0.003, 0.004, 0.0]))
    translation_m, rotation_deg = pose_error(estimate, truth)
    assert translation_m == pytest.approx(0.005)
    assert rotation_deg == pytest.approx(0.5)
    assert rotation_angle_deg(np.eye(3)) == 0.0
