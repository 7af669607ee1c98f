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
    stacked = _Stacked(edges)
    poses = _gauss_newton(T_field_node, fixed, stacked, active, None, iterations)[0]
    for scale in GRADUATION:  # graduated non-convexity: wide kernel first, then narrower
        wide = Tolerance(scale * tolerance.translation_m, scale * tolerance.rotation_deg)
        poses = _gauss_newton(poses, fixed, stacked, active, wide, iterations)[0]
    dropped: list[int] = []
    while True:
        r = stacked.at(poses, active)[2]
        weights = dict(zip(active, _weights(r, tolerance).tolist(), strict=True))
        worst = min((k for k in active if edges[k].robust), key=lambda k: weights[k], default=None)
        if worst is None or weights[worst] >= PRUNE_WEIGHT:
            break
        active.remove(worst)  # the worst first: one bad edge can make its neighbours look bad
        dropped.append(worst)
        poses = _gauss_newton(poses, fixed, stacked, active, None, iterations)[0]
    poses, H = _gauss_newton(poses, fixed, stacked, active, None, iterations)
    solution = Solution(poses, active, sorted(dropped))
    final = dict(zip(active, stacked.at(poses, active)[2], strict=True))
    solution.residuals = {k: disagreement(r) for k, r in final.items()}
    _add_covariance(solution, fixed, edges, H, relative_to, final)
    return solution


def _weights(r: NDArray[np.float64], tolerance: Tolerance) -> NDArray[np.float64]:
    """(E,) the line process's weight of each residual of ``r`` (E, 6)."""
    translation_m = np.linalg.norm(r[:, 3:], axis=1)
    rotation_deg = np.degrees(np.linalg.norm(r[:, :3], axis=1))
    u2 = (translation_m / tolerance.translation_m) ** 2 + (
        rotation_deg / tolerance.rotation_deg
    ) ** 2
    weights: NDArray[np.float64] = (1.0 / (1.0 + u2)) ** 2
    return weights


class _Stacked:
    """The edges as arrays, so that every edge's residual and Jacobian is computed at once:
    ``Z_a_b`` inverted (E, 4, 4), the information (E, 6, 6), the end nodes and which edges
    are robust. The same arithmetic as :func:`residual` and :func:`se3.adjoint`, edge by
    edge (a 7 x 7 plot's graph was solved 46 times, 900 Gauss-Newton steps, in 15 s of
    Python loops over its edges)."""

    def __init__(self, edges: list[Edge]) -> None:
        self.a = np.array([e.a for e in edges], dtype=np.int64)
        self.b = np.array([e.b for e in edges], dtype=np.int64)
        self.robust = np.array([e.robust for e in edges], dtype=bool)
        self.Z_inverse = np.array([invert(e.Z_a_b) for e in edges]).reshape(-1, 4, 4)
        self.information = np.array([e.information for e in edges]).reshape(-1, 6, 6)

    def at(
        self, poses: dict[int, Matrix4], active: list[int]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The ``active`` edges (indices) at ``poses``: each one's pose of a and of b (A, 4, 4)
        and its residual (A, 6), :func:`residual`."""
        k = np.asarray(active, dtype=np.intp)
        T_a, T_b = _poses(poses, self.a[k]), _poses(poses, self.b[k])
        return T_a, T_b, se3.logs(self.Z_inverse[k] @ _inverted(T_a) @ T_b)


def _poses(poses: dict[int, Matrix4], nodes: NDArray[np.int64]) -> NDArray[np.float64]:
    """(K, 4, 4) the poses of ``nodes``."""
    return np.array([poses[int(n)] for n in nodes]).reshape(-1, 4, 4)


def _inverted(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """(K, 4, 4) the inverses of the rigid motions ``T`` (K, 4, 4)."""
    out = np.zeros_like(T)
    R_t = np.swapaxes(T[:, :3, :3], 1, 2)
    out[:, :3, :3] = R_t
    out[:, :3, 3] = -np.einsum("kij,kj->ki", R_t, T[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def _gauss_newton(
    poses_in: dict[int, Matrix4],
    fixed: set[int],
    edges: _Stacked,
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
    edges: _Stacked,
    active: list[int],
    tolerance: Tolerance | None,
) -> tuple[scipy.sparse.csc_matrix, NDArray[np.float64]]:
    """The normal matrix (sparse, free nodes in ``index``'s order, 6 x 6 blocks) and the
    gradient of the ``active`` edges at ``poses``; robust edges weighted by the line process
    when ``tolerance`` is given. Edge b's Jacobian of the residual is the identity, edge a's
    ``-adjoint(T_b^-1 T_a)``."""
    size = 6 * len(index)
    k = np.asarray(active, dtype=np.intp)
    T_a, T_b, r = edges.at(poses, active)
    w = np.ones(len(k))
    if tolerance is not None:
        w = np.where(edges.robust[k], _weights(r, tolerance), 1.0)
    information = w[:, None, None] * edges.information[k]
    J_a = -se3.adjoints(_inverted(T_b) @ T_a)
    J = (J_a, np.broadcast_to(np.eye(6), J_a.shape))  # each edge's Jacobian at a, at b
    slot = (  # each end's free-node index, -1 where the node is fixed
        np.array([index.get(int(n), -1) for n in edges.a[k]], dtype=np.intp),
        np.array([index.get(int(n), -1) for n in edges.b[k]], dtype=np.intp),
    )
    g = np.zeros(size)
    offsets = np.arange(6)
    rows, cols, data = [], [], []
    for n in (0, 1):
        Jt_info = np.swapaxes(J[n], 1, 2) @ information  # (A, 6, 6)
        on = slot[n] >= 0
        np.add.at(g.reshape(-1, 6), slot[n][on], np.einsum("kij,kj->ki", Jt_info[on], r[on]))
        for m in (0, 1):
            both = on & (slot[m] >= 0)
            block = Jt_info[both] @ J[m][both]  # (B, 6, 6)
            rows.append((6 * slot[n][both])[:, None] + np.repeat(offsets, 6)[None, :])
            cols.append((6 * slot[m][both])[:, None] + np.tile(offsets, 6)[None, :])
            data.append(block.reshape(-1, 36))
    # a node with no active edge stays where it is
    diagonal = 6 * np.arange(len(index))[:, None] + offsets[None, :]
    rows.append(diagonal)
    cols.append(diagonal)
    data.append(np.full(diagonal.shape, 1e-9))
    H = scipy.sparse.csc_matrix(
        (
            np.concatenate([d.ravel() for d in data]),
            (np.concatenate([x.ravel() for x in rows]), np.concatenate([x.ravel() for x in cols])),
        ),
        shape=(size, size),
    )
    return H, g


def _add_covariance(
    solution: Solution,
    fixed: set[int],
    edges: list[Edge],
    H: scipy.sparse.csc_matrix,
    relative_to: int | None,
    residuals: dict[int, se3.Vector6],
) -> None:
    """Covariances of the free nodes (relative to ``relative_to`` when given), scaled by the
    variance factor (the robust edges' mean squared Mahalanobis residual per degree of
    freedom, at least 1; ``residuals``: each kept edge's at the solution)."""
    free = sorted(n for n in solution.T_field_node if n not in fixed)
    robust = [k for k in solution.kept if edges[k].robust]
    if robust:
        chi2 = sum(float(residuals[k] @ edges[k].information @ residuals[k]) for k in robust)
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
