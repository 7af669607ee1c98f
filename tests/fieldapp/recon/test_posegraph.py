"""The pose graph's arithmetic, every edge at once: the twists and adjoints against their
definitions, and a graph of known poses solved back, its outlier dropped."""

from __future__ import annotations

import numpy as np
import pytest

from devices.geometry import invert
from fieldapp.recon import posegraph, se3


def _twists(rng: np.random.Generator) -> np.ndarray:
    """Twists of every kind the branches tell apart: turns of up to about 100 degrees, turns
    under 1e-7 rad, no turn at all, no motion at all."""
    twists = rng.normal(size=(60, 6)) * [0.6, 0.6, 0.6, 1.0, 1.0, 1.0]
    twists[10:20, :3] *= 1e-9
    twists[20:25, :3] = 0.0
    twists[25:28] = 0.0
    return twists


def test_the_log_of_every_motion_at_once_is_its_twist() -> None:
    twists = _twists(np.random.default_rng(0))
    T = np.array([se3.exp(xi) for xi in twists])
    np.testing.assert_allclose(se3.logs(T), twists, rtol=0, atol=1e-12)
    assert se3.logs(T[:0]).shape == (0, 6)


def test_the_adjoint_carries_a_right_perturbation_to_the_left() -> None:
    """T @ exp(xi) = exp(adjoint(T) @ xi) @ T, for every motion at once."""
    rng = np.random.default_rng(1)
    T = np.array([se3.exp(xi) for xi in _twists(rng)])
    xi = rng.normal(size=(len(T), 6)) * 0.1
    A = se3.adjoints(T)
    for Tk, Ak, xk in zip(T, A, xi, strict=True):
        np.testing.assert_allclose(Tk @ se3.exp(xk), se3.exp(Ak @ xk) @ Tk, atol=1e-12)


def _ring(rng: np.random.Generator, noise: float) -> tuple[dict[int, np.ndarray], list]:
    """Six stations on a ring, each edge to the next two measured with ``noise`` (twist
    standard deviation): the true poses and the edges."""
    truth = {
        n: se3.exp(np.array([0, 0, 0.3 * n, 1.6 * np.cos(n), 1.6 * np.sin(n), 0.01 * n]))
        for n in range(6)
    }
    edges = []
    for a in range(6):
        for step in (1, 2):
            b = (a + step) % 6
            Z = invert(truth[a]) @ truth[b] @ se3.exp(rng.normal(size=6) * noise)
            edges.append(posegraph.Edge(a, b, Z, np.eye(6) * 1e4))
    return truth, edges


def test_the_normal_equations_vanish_at_poses_every_edge_agrees_with() -> None:
    truth, edges = _ring(np.random.default_rng(1), noise=0.0)
    index = {n: i for i, n in enumerate(range(1, 6))}
    H, g = posegraph._normal_equations(
        truth, index, posegraph._Stacked(edges), list(range(len(edges))), None
    )
    assert np.abs(g).max() < 1e-9
    dense = H.toarray()
    np.testing.assert_allclose(dense, dense.T, atol=1e-6)
    assert np.linalg.eigvalsh(dense).min() > 0.0  # the ring holds every free station


@pytest.mark.parametrize("seed", [2, 3])
def test_a_ring_is_solved_back_and_its_outlier_dropped(seed: int) -> None:
    rng = np.random.default_rng(seed)
    truth, edges = _ring(rng, noise=1e-4)
    wrong = posegraph.Edge(
        0, 3, invert(truth[0]) @ truth[3] @ se3.exp(np.r_[0, 0, 0.2, 0.3, 0, 0]), np.eye(6) * 1e4
    )
    start = {n: T @ se3.exp(rng.normal(size=6) * 0.02) if n else T for n, T in truth.items()}
    solution = posegraph.solve(
        start, {0}, [*edges, wrong], posegraph.Tolerance(0.01, 0.5), relative_to=1
    )
    assert solution.dropped == [len(edges)]  # the outlier, and only it
    for n, T in truth.items():
        shift_m, turn_deg = posegraph.disagreement(se3.log(invert(T) @ solution.T_field_node[n]))
        assert shift_m < 1e-3 and turn_deg < 0.05, (n, shift_m, turn_deg)
