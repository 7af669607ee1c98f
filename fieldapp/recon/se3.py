"""Rigid motions as 6-vectors ``[rotation (rad), translation (m)]`` for the pose graph.

``exp(xi)`` and ``log(T)`` are the SE(3) exponential and logarithm (Rodrigues, with the left
Jacobian for the translation); ``adjoint(T)`` maps a right perturbation of ``T @ B`` onto a left
one: ``T @ exp(xi) = exp(adjoint(T) @ xi) @ T``. ``logs`` and ``adjoints`` take many motions at
once (the pose graph's edges); ``log`` and ``adjoint`` are they on one motion.
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
    matrix: NDArray[np.float64] = _skews(np.asarray(v, dtype=np.float64)[None])[0]
    return matrix


def _skews(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """(K, 3, 3) cross-product matrices of ``v`` (K, 3)."""
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return K


def _left_jacobians(phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """(K, 3, 3) SO(3)'s left Jacobian at each rotation vector of ``phi`` (K, 3)."""
    angle = np.linalg.norm(phi, axis=1)
    K = _skews(phi)
    J: NDArray[np.float64] = np.eye(3) + 0.5 * K
    turned = angle >= _SMALL
    if turned.any():
        n = angle[turned][:, None, None]
        Kt = K[turned]
        J[turned] = np.eye(3) + (1.0 - np.cos(n)) / n**2 * Kt + (n - np.sin(n)) / n**3 * (Kt @ Kt)
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
    T[:3, 3] = _left_jacobians(phi[None])[0] @ rho
    return T


def log(T: Matrix4) -> Vector6:
    """The twist (6,) of the rigid motion ``T`` (rotation below 180 degrees)."""
    twist: Vector6 = logs(np.asarray(T, dtype=np.float64)[None])[0]
    return twist


def logs(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """(K, 6) the twist of each rigid motion of ``T`` (K, 4, 4), rotations below 180 degrees."""
    R = T[:, :3, :3]
    cos_angle = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos_angle)
    axis = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], 1)
    small = angle < 1e-7
    scale = np.where(small, 0.5, angle / (2.0 * np.sin(np.where(small, 1.0, angle))))
    phi = scale[:, None] * axis
    rho = np.linalg.solve(_left_jacobians(phi), T[:, :3, 3:4])[:, :, 0]
    return np.concatenate([phi, rho], axis=1)


def adjoint(T: Matrix4) -> NDArray[np.float64]:
    """(6, 6) adjoint of ``T`` for ``[rotation, translation]`` twists."""
    A: NDArray[np.float64] = adjoints(np.asarray(T, dtype=np.float64)[None])[0]
    return A


def adjoints(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """(K, 6, 6) :func:`adjoint` of each rigid motion of ``T`` (K, 4, 4)."""
    R, t = T[:, :3, :3], T[:, :3, 3]
    A = np.zeros((len(T), 6, 6))
    A[:, :3, :3] = R
    A[:, 3:, 3:] = R
    A[:, 3:, :3] = _skews(t) @ R
    return A
