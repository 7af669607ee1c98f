"""Rigid motions as 6-vectors ``[rotation (rad), translation (m)]`` for the pose graph.

``exp(xi)`` and ``log(T)`` are the SE(3) exponential and logarithm (Rodrigues, with the left
Jacobian for the translation); ``adjoint(T)`` maps a right perturbation of ``T @ B`` onto a left
one: ``T @ exp(xi) = exp(adjoint(T) @ xi) @ T``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4

Vector6 = NDArray[np.float64]
"""(6,) float64: rotation vector (rad) then translation (m)."""

_SMALL = 1e-10


def skew(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3, 3) cross-product matrix of ``v`` (3,)."""
    matrix: NDArray[np.float64] = np.array(
        [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]
    )
    return matrix


def _left_jacobian(phi: NDArray[np.float64]) -> NDArray[np.float64]:
    angle = float(np.linalg.norm(phi))
    K = skew(phi)
    J: NDArray[np.float64] = np.eye(3) + 0.5 * K
    if angle >= _SMALL:
        J = (
            np.eye(3)
            + (1.0 - np.cos(angle)) / angle**2 * K
            + (angle - np.sin(angle)) / angle**3 * (K @ K)
        )
    return J


def exp(xi: Vector6) -> Matrix4:
    """The rigid motion (4, 4) of the twist ``xi``."""
    phi, rho = xi[:3], xi[3:]
    angle = float(np.linalg.norm(phi))
    K = skew(phi)
    if angle < _SMALL:
        R = np.eye(3) + K
    else:
        R = np.eye(3) + np.sin(angle) / angle * K + (1.0 - np.cos(angle)) / angle**2 * (K @ K)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = _left_jacobian(phi) @ rho
    return T


def log(T: Matrix4) -> Vector6:
    """The twist (6,) of the rigid motion ``T`` (rotation below 180 degrees)."""
    R = T[:3, :3]
    cos_angle = float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    angle = float(np.arccos(cos_angle))
    if angle < 1e-7:
        phi = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    else:
        axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
        phi = angle / (2.0 * np.sin(angle)) * axis
    rho = np.linalg.solve(_left_jacobian(phi), T[:3, 3])
    return np.concatenate([phi, rho])


def adjoint(T: Matrix4) -> NDArray[np.float64]:
    """(6, 6) adjoint of ``T`` for ``[rotation, translation]`` twists."""
    R, t = T[:3, :3], T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[3:, 3:] = R
    A[3:, :3] = skew(t) @ R
    return A
