"""The BLAS-free products equal numpy's."""

from __future__ import annotations

import numpy as np

from devices.geometry import make_transform, rotation_x, rotation_z, transform_points
from devices.sim.linalg import apply, rotate_t


def test_rotate_and_apply_match_matmul() -> None:
    rng = np.random.default_rng(0)
    R = rotation_z(30.0) @ rotation_x(-50.0)
    vectors = rng.normal(size=(1000, 3))
    np.testing.assert_allclose(rotate_t(R, vectors.T.copy()), vectors @ R.T, rtol=1e-5, atol=1e-5)
    T = make_transform(R, np.array([1.0, -2.0, 0.5]))
    np.testing.assert_allclose(apply(T, vectors), transform_points(T, vectors), atol=1e-12)
