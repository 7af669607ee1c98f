"""The weighted SVD rigid fit (paper Eqs. 3-8) against known transforms."""

from __future__ import annotations

import numpy as np
import pytest

from devices.camera.frames import KINECT_V2_PAPER
from devices.geometry import make_transform, pose_error, rotation_x, rotation_z, transform_points
from fieldapp.calib.corners3d import lift_corners
from fieldapp.calib.rigid import fit_rigid_weighted
from fieldapp.errors import FieldappError


def test_recovers_a_known_transform_exactly():
    rng = np.random.default_rng(1)
    source = rng.uniform(-1, 1, (40, 3))
    T = make_transform(rotation_z(45.0) @ rotation_x(3.0), np.array([0.12, -0.05, 0.3]))
    fit = fit_rigid_weighted(source, transform_points(T, source))
    np.testing.assert_allclose(fit.T_target_source, T, atol=1e-12)
    assert fit.rmse_m < 1e-12


def test_weights_discount_a_bad_point():
    rng = np.random.default_rng(2)
    source = rng.uniform(-1, 1, (30, 3))
    T = make_transform(rotation_z(-45.0), np.array([0.1, 0.0, 0.0]))
    target = transform_points(T, source)
    target[0] += [0.2, 0.0, 0.0]  # one corner with a bad depth
    weights = np.ones(30)
    unweighted = fit_rigid_weighted(source, target)
    weights[0] = 1e-6
    weighted = fit_rigid_weighted(source, target, weights)
    assert pose_error(weighted.T_target_source, T)[0] < 1e-5
    assert pose_error(unweighted.T_target_source, T)[0] > 1e-3


def test_never_returns_a_reflection():
    rng = np.random.default_rng(3)
    source = rng.uniform(-1, 1, (20, 3))
    mirrored = source * [1.0, 1.0, -1.0]  # no rotation maps one to the other
    fit = fit_rigid_weighted(source, mirrored)
    assert np.linalg.det(fit.T_target_source[:3, :3]) == pytest.approx(1.0)


def test_planar_points_are_fine():
    grid = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.04
    source = np.column_stack([grid, np.zeros(len(grid))])
    T = make_transform(rotation_z(45.0), np.array([0.3, 0.1, 1.2]))
    fit = fit_rigid_weighted(source, transform_points(T, source))
    np.testing.assert_allclose(fit.T_target_source, T, atol=1e-10)


def test_too_few_points():
    with pytest.raises(FieldappError, match="at least 3"):
        fit_rigid_weighted(np.zeros((2, 3)), np.zeros((2, 3)))


def test_lifting_a_corner_uses_the_local_plane_not_one_pixel():
    k = KINECT_V2_PAPER
    rng = np.random.default_rng(4)
    # a tilted plane z = 1.5 + 0.2 x seen by the camera, with 2 mm noise and a dropout
    u, _ = np.meshgrid(np.arange(k.width), np.arange(k.height))
    x_over_z = (u - k.cx) / k.fx
    depth = (1.5 / (1.0 - 0.2 * x_over_z)).astype(np.float32)
    noisy = depth + rng.normal(0, 0.002, depth.shape).astype(np.float32)
    noisy[200, 300] = np.nan
    corners = np.array([[300.3, 200.7], [100.5, 50.25]], np.float32)
    lifted = lift_corners(corners, noisy, k)
    assert lifted.valid.all()
    for (cu, cv), point in zip(corners, lifted.points_m, strict=True):
        ray = np.array([(cu - k.cx) / k.fx, (cv - k.cy) / k.fy, 1.0])
        z_true = 1.5 / (1.0 - 0.2 * ray[0])
        np.testing.assert_allclose(point, ray * z_true, atol=0.0012)


def test_lifting_reports_missing_depth():
    k = KINECT_V2_PAPER
    depth = np.full((k.height, k.width), np.nan, np.float32)
    lifted = lift_corners(np.array([[10.0, 10.0]], np.float32), depth, k)
    assert not lifted.valid.any()
