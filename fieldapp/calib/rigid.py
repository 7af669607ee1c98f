"""Weighted least-squares rigid transform between corresponding 3D points (the paper's
Eqs. 3-8: weighted centroids, weighted cross-covariance, SVD, reflection case handled)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, make_transform, transform_points
from fieldapp.errors import FieldappError


@dataclass(frozen=True)
class RigidFit:
    T_target_source: Matrix4
    rmse_m: float
    """Root mean square distance between the moved source points and the targets."""
    max_error_m: float


def fit_rigid_weighted(
    source: NDArray[np.float64],
    target: NDArray[np.float64],
    weights: NDArray[np.float64] | None = None,
) -> RigidFit:
    """``T_target_source`` minimising sum w_i |R s_i + t - t_i|^2.

    ``source``, ``target``: (N, 3) corresponding points; ``weights``: (N,) non-negative.
    """
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError("source and target must both be (N, 3)")
    w = np.ones(len(source)) if weights is None else np.asarray(weights, np.float64)
    if len(source) < 3 or np.count_nonzero(w > 0) < 3:
        raise FieldappError("at least 3 weighted point pairs are needed for a rigid fit")
    w = w / w.sum()
    source_mean, target_mean = w @ source, w @ target  # Eq. 3: weighted centroids
    H = (source - source_mean).T @ ((target - target_mean) * w[:, None])  # Eq. 5
    U, _, Vt = np.linalg.svd(H)  # Eq. 6
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])  # reflection guard
    R = Vt.T @ D @ U.T  # Eq. 7
    t = target_mean - R @ source_mean  # Eq. 8
    T = make_transform(R, t)
    residuals = np.linalg.norm(transform_points(T, source) - target, axis=1)
    return RigidFit(T, float(np.sqrt(np.mean(residuals**2))), float(residuals.max()))
