"""The collar: a path pays no bend cost where it turns from its *own* stem onto a leaf
(``StemSettings.collar_radius_m``), while a neighbour's path still pays for every bend."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from fieldapp.recon.plants import assign_by_settings
from fieldapp.recon.settings import StemSettings

from .synthetic import cylinder


def _ribbon(
    rng: np.random.Generator, start: list[float], end: list[float], n: int
) -> NDArray[np.float64]:
    """(n, 3) points on a flat 6 cm ribbon from ``start`` to ``end``, level across."""
    u = rng.uniform(0.0, 1.0, n)[:, None]
    across = rng.uniform(-0.03, 0.03, n)
    points = np.asarray(start) + u * (np.asarray(end) - np.asarray(start))
    points[:, 1] += across
    return points + rng.normal(0.0, 0.001, points.shape)


def _pair(rng: np.random.Generator) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A: a stem 2.4 cm thick at the origin and a level leaf leaving it at a right angle 5 cm
    above the stem's foot band (the sharp collar), 48 cm along +x. B, 0.8 m away: a leaf that
    leaves its stem within the foot band and rises gently towards A, its tip lying on A's leaf
    40 cm from A's stem (14 degrees between them)."""
    a = np.concatenate(
        [
            cylinder(rng, 0.0, 0.0, 0.012, 0.35, 4000),
            _ribbon(rng, [0.013, 0.0, 0.20], [0.48, 0.0, 0.20], 5000),
        ]
    )
    b = np.concatenate(
        [
            cylinder(rng, 0.8, 0.0, 0.012, 0.35, 4000),
            _ribbon(rng, [0.787, 0.0, 0.10], [0.40, 0.0, 0.195], 5000),
        ]
    )
    return a, b


def _own_leaf_share(collar_radius_m: float, seed: int) -> tuple[float, float]:
    a, b = _pair(np.random.default_rng(seed))
    settings = StemSettings(collar_radius_m=collar_radius_m, collar_height_m=0.10)
    stems = np.array([[0.0, 0.0], [0.8, 0.0]])
    assignment = assign_by_settings(np.concatenate([a, b]), stems, settings)
    leaf_a = np.zeros(len(a) + len(b), dtype=bool)
    leaf_a[4000 : len(a)] = True
    leaf_b = np.zeros(len(a) + len(b), dtype=bool)
    leaf_b[len(a) + 4000 :] = True
    return (
        float(np.mean(assignment.stem[leaf_a] == 0)),
        float(np.mean(assignment.stem[leaf_b] == 1)),
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_leaf_leaving_its_stem_at_a_sharp_collar_stays_with_its_plant(seed: int) -> None:
    own_a, own_b = _own_leaf_share(0.03, seed)
    assert own_a > 0.9 and own_b > 0.95  # A loses a little where B's tip lies on it


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_without_the_collar_the_neighbour_takes_the_leaf(seed: int) -> None:
    """Why the setting exists: A's own path pays the right angle at its collar, B's reaches
    A's leaf across a gentle contact, and takes most of it."""
    own_a, own_b = _own_leaf_share(0.0, seed)
    assert own_a < 0.3 and own_b > 0.95
