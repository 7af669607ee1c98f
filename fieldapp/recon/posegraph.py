"""A pose graph of the plot's stations and its robust least-squares solution.

Nodes are station poses ``T_field_node`` (a node's frame sits at its station's ground centre, so
a correction turns a station about its own axis). An edge ``a <- b`` measures ``Z_a_b`` (node b
in node a) with a (6, 6) information matrix in b's frame, twists ordered ``[rotation,
translation]``. The residual of an edge is ``log(Z_a_b^-1 @ T_field_a^-1 @ T_field_b)``.

Solved by Gauss-Newton on the right perturbation of every free node, the sparse normal
equations by SuperLU (one thread, so the result never depends on the machine). Edges marked
``robust`` go through a line process (Geman-McClure weights ``(1 / (1 + u^2))^2``, ``u`` the
edge's disagreement in units of its tolerance): first plain least squares, then the weighted
solution with a kernel narrowing from 16 tolerances to 2 (graduated non-convexity), then
edges whose weight falls below 1/4 (disagreement above tolerance) are dropped, the worst
first, and the rest solved again by plain least squares, as Open3D's global optimisation does
with its line process. (Narrowing the kernel to one tolerance let the priors win over the
down-weighted edges and drag good stations back towards their coarse poses.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert
from fieldapp.recon import se3

GRADUATION = (16.0, 4.0, 2.0)
"""The robust kernel's width, in tolerances, from the first robust solution to the last: a
narrow kernel from the start would call every edge an outlier of the coarse poses."""

PRUNE_WEIGHT = 0.25
"""Robust edges whose line-process weight ends below this are dropped (Open3D's default)."""


@dataclass(frozen=True)
class Edge:
    """``Z_a_b`` maps node ``b`` into node ``a``; ``information`` (6, 6) in b's frame."""

    a: int
    b: int
    Z_a_b: Matrix4
    information: NDArray[np.float64]
    robust: bool = True


@dataclass(frozen=True)
class Tolerance:
    """How far a robust edge may disagree with the solution before it counts as an outlier."""

    translation_m: float
    rotation_deg: float


@dataclass
class Solution:
    """Optimised poses, the edges kept and dropped (indices into the input list), each kept
    edge's residual (translation m, rotation deg) and each free node's (6, 6) covariance,
    scaled by the a-posteriori variance factor of the robust edges."""

    T_field_node: dict[int, Matrix4]
    kept: list[int]
    dropped: list[int]
    residuals: dict[int, tuple[float, float]] = field(default_factory=dict)
    covariance: dict[int, NDArray[np.float64]] = field(default_factory=dict)
    variance_factor: float = 1.0


def residual(edge: Edge, poses: dict[int, Matrix4]) -> se3.Vector6:
    """The edge's (6,) disagreement with ``poses``."""
    return se3.log(invert(edge.Z_a_b) @ invert(poses[edge.a]) @ poses[edge.b])


def disagreement(r: se3.Vector6) -> tuple[float, float]:
    """(translation m, rotation deg) of a residual."""
    return float(np.linalg.norm(r[3:])), float(np.degrees(np.linalg.norm(r[:3])))


def solve(
    T_field_node: dict[int, Matrix4],
    fixed: set[int],
    edges: list[Edge],
    tolerance: Tolerance,
    iterations: int = 30,
    relative_to: int | None = None,
) -> Solution:
    """Optimise the free nodes of the graph; see the module's docstring for the steps.
    Covariances are of each node relative to ``relative_to`` when given (a free node)."""
    active = list(range(len(edges)))
    poses = _gauss_newton(T_field_node, fixed, edges, active, None, iterations)[0]
    for scale in GRADUATION:  # graduated non-convexity: wide kernel first, then narrower
        wide = Tolerance(scale * tolerance.translation_m, scale * tolerance.rotation_deg)
        poses = _gauss_newton(poses, fixed, edges, active, wide, iterations)[0]
    dropped: list[int] = []
    while True:
        weights = {k: _weight(residual(edges[k], poses), tolerance) for k in active}
        worst = min((k for k in active if edges[k].robust), key=lambda k: weights[k], default=None)
        if worst is None or weights[worst] >= PRUNE_WEIGHT:
            break
        active.remove(worst)  # the worst first: one bad edge can make its neighbours look bad
        dropped.append(worst)
        poses = _gauss_newton(poses, fixed, edges, active, None, iterations)[0]
    poses, H = _gauss_newton(poses, fixed, edges, active, None, iterations)
    solution = Solution(poses, active, sorted(dropped))
    solution.residuals = {k: disagreement(residual(edges[k], poses)) for k in active}
    _add_covariance(solution, fixed, edges, H, relative_to)
    return solution


def _weight(r: se3.Vector6, tolerance: Tolerance) -> float:
    translation_m, rotation_deg = disagreement(r)
    u2 = (translation_m / tolerance.translation_m) ** 2 + (
        rotation_deg / tolerance.rotation_deg
    ) ** 2
    return float((1.0 / (1.0 + u2)) ** 2)


def _gauss_newton(
    poses_in: dict[int, Matrix4],
    fixed: set[int],
    edges: list[Edge],
    active: list[int],
    tolerance: Tolerance | None,
    iterations: int,
) -> tuple[dict[int, Matrix4], scipy.sparse.csc_matrix]:
    """Gauss-Newton; robust edges weighted by the line process when ``tolerance`` is given.
    Returns the poses and the last normal matrix (free nodes in sorted order)."""
    poses = dict(poses_in)
    free = sorted(n for n in poses if n not in fixed)
    index = {n: i for i, n in enumerate(free)}
    H = scipy.sparse.csc_matrix((6 * len(free), 6 * len(free)))
    for _ in range(iterations):
        H, g = _normal_equations(poses, index, edges, active, tolerance)
        if not free:
            break
        step = scipy.sparse.linalg.splu(H).solve(-g)
        for node, i in index.items():
            poses[node] = poses[node] @ se3.exp(step[6 * i : 6 * i + 6])
        if np.max(np.abs(step)) < 1e-10:
            break
    return poses, H


def _normal_equations(
    poses: dict[int, Matrix4],
    index: dict[int, int],
    edges: list[Edge],
    active: list[int],
    tolerance: Tolerance | None,
) -> tuple[scipy.sparse.csc_matrix, NDArray[np.float64]]:
    size = 6 * len(index)
    blocks: dict[tuple[int, int], NDArray[np.float64]] = {}
    g = np.zeros(size)
    for k in active:
        edge = edges[k]
        r = residual(edge, poses)
        w = _weight(r, tolerance) if tolerance is not None and edge.robust else 1.0
        jacobians = {edge.b: np.eye(6), edge.a: -se3.adjoint(invert(poses[edge.b]) @ poses[edge.a])}
        information = w * edge.information
        for n, Jn in jacobians.items():
            if n not in index:
                continue
            g[6 * index[n] : 6 * index[n] + 6] += Jn.T @ information @ r
            for m, Jm in jacobians.items():
                if m in index:
                    key = (index[n], index[m])
                    blocks[key] = blocks.get(key, 0.0) + Jn.T @ information @ Jm
    for i in range(len(index)):  # a node with no active edge stays where it is
        blocks[(i, i)] = blocks.get((i, i), 0.0) + 1e-9 * np.eye(6)
    rows, cols, data = [], [], []
    offsets = np.arange(6)
    for (i, j), block in sorted(blocks.items()):
        rows.append(np.repeat(6 * i + offsets, 6))
        cols.append(np.tile(6 * j + offsets, 6))
        data.append(np.asarray(block).ravel())
    if not rows:
        return scipy.sparse.csc_matrix((size, size)), g
    H = scipy.sparse.csc_matrix(
        (np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=(size, size)
    )
    return H, g


def _add_covariance(
    solution: Solution,
    fixed: set[int],
    edges: list[Edge],
    H: scipy.sparse.csc_matrix,
    relative_to: int | None,
) -> None:
    """Covariances of the free nodes (relative to ``relative_to`` when given), scaled by the
    variance factor (the robust edges' mean squared Mahalanobis residual per degree of
    freedom, at least 1)."""
    free = sorted(n for n in solution.T_field_node if n not in fixed)
    robust = [k for k in solution.kept if edges[k].robust]
    if robust:
        chi2 = sum(
            float(r @ edges[k].information @ r)
            for k in robust
            for r in [residual(edges[k], solution.T_field_node)]
        )
        solution.variance_factor = max(1.0, chi2 / (6 * len(robust)))
    if not free:
        return
    lu = scipy.sparse.linalg.splu(H)
    index = {n: i for i, n in enumerate(free)}
    anchor = None
    if relative_to is not None:
        unit = np.zeros((H.shape[0], 6))
        unit[6 * index[relative_to] : 6 * index[relative_to] + 6] = np.eye(6)
        anchor = lu.solve(unit)  # columns of H^-1 for the anchor node
    poses = solution.T_field_node
    for node, i in index.items():
        unit = np.zeros((H.shape[0], 6))
        unit[6 * i : 6 * i + 6] = np.eye(6)
        columns = lu.solve(unit)
        own = columns[6 * i : 6 * i + 6]
        if anchor is not None and relative_to is not None and node != relative_to:
            j = index[relative_to]
            A = -se3.adjoint(invert(poses[node]) @ poses[relative_to])
            cross = columns[6 * j : 6 * j + 6].T  # cov(node, anchor)
            anchor_own = anchor[6 * j : 6 * j + 6]
            own = own + A @ anchor_own @ A.T + cross @ A.T + A @ cross.T
        elif node == relative_to:
            own = np.zeros((6, 6))
        solution.covariance[node] = solution.variance_factor * own
