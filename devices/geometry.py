"""Rigid transforms as 4 x 4 numpy arrays, shared by the simulators and the core.

Naming follows the house style: ``T_a_b`` maps coordinates in frame ``b`` into frame ``a``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Matrix4 = NDArray[np.float64]
"""A 4 x 4 homogeneous rigid transform, float64."""

ROTATION_TOLERANCE = 1e-4
"""Largest |R^T R - I| entry and |det R - 1| accepted as a rotation (JSON round-off)."""


def make_transform(rotation: NDArray[np.float64], translation_m: NDArray[np.float64]) -> Matrix4:
    """Build ``T`` from a (3, 3) rotation and a (3,) translation in metres."""
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = translation_m
    return T


def rotation_x(angle_deg: float) -> NDArray[np.float64]:
    """(3, 3) rotation about the x axis (right-handed)."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle_deg: float) -> NDArray[np.float64]:
    """(3, 3) rotation about the y axis (right-handed)."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle_deg: float) -> NDArray[np.float64]:
    """(3, 3) rotation about the z axis (right-handed)."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def invert(T: Matrix4) -> Matrix4:
    """Inverse of a rigid transform (no general matrix inverse)."""
    R, t = T[:3, :3], T[:3, 3]
    return make_transform(R.T, -R.T @ t)


def transform_points(T: Matrix4, points: NDArray[np.floating]) -> NDArray[np.float64]:
    """Apply ``T`` to ``points`` (N, 3); returns (N, 3) float64."""
    return np.asarray(points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]


def fit_plan_motion(source_xy: NDArray[np.float64], target_xy: NDArray[np.float64]) -> Matrix4:
    """The motion in plan view (a turn about z and a shift in x and y, z unchanged) taking
    ``source_xy`` (N, 2) onto the corresponding ``target_xy`` (N, 2) in the least squares
    sense (Kabsch in 2-D, no reflection); N >= 2 with two distinct points."""
    source_mean, target_mean = source_xy.mean(axis=0), target_xy.mean(axis=0)
    covariance = (source_xy - source_mean).T @ (target_xy - target_mean)
    u, _, vt = np.linalg.svd(covariance)
    sign = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    turn = vt.T @ np.diag([1.0, sign]) @ u.T
    R = rotation_z(float(np.degrees(np.arctan2(turn[1, 0], turn[0, 0]))))
    return make_transform(R, np.append(target_mean - R[:2, :2] @ source_mean, 0.0))


def rigidity_problem(T: NDArray[np.float64]) -> str | None:
    """Why ``T`` is not a finite 4 x 4 rigid transform, or ``None`` when it is one."""
    if T.shape != (4, 4):
        return f"must be 4 x 4, got shape {T.shape}"
    if not np.all(np.isfinite(T)):
        return "has a NaN or infinite entry"
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        return f"last row must be 0 0 0 1, got {T[3].tolist()}"
    R = T[:3, :3]
    largest = float(np.abs(R).max())
    if largest > 1.0 + ROTATION_TOLERANCE:  # no entry of a rotation exceeds 1 (and R^T R of
        return f"rotation part is not orthonormal (an entry is {largest:.3g})"  # 1e154 overflows)
    deviation = float(np.abs(R.T @ R - np.eye(3)).max())
    if deviation > ROTATION_TOLERANCE:
        return f"rotation part is not orthonormal (|R^T R - I| = {deviation:.2g})"
    det = float(np.linalg.det(R))
    if abs(det - 1.0) > ROTATION_TOLERANCE:
        return f"rotation part has determinant {det:.4g}, not +1 (a reflection?)"
    return None


def rotation_angle_deg(R: NDArray[np.float64]) -> float:
    """Angle of the rotation ``R`` (3, 3) in degrees, in [0, 180]."""
    cos_angle = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos_angle)))


def pose_error(T_estimate: Matrix4, T_truth: Matrix4) -> tuple[float, float]:
    """(translation error in metres, rotation error in degrees) between two poses."""
    delta = invert(T_truth) @ T_estimate
    return float(np.linalg.norm(delta[:3, 3])), rotation_angle_deg(delta[:3, :3])
