"""Synthetic maize-like plants whose leaves cross and touch, with each plant's own points."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .synthetic import cylinder


def leaf(
    rng: np.random.Generator,
    foot_xy: tuple[float, float],
    azimuth_deg: float,
    node_z_m: float,
    length_m: float,
    rise_m: float,
    n: int,
) -> NDArray[np.float64]:
    """(n, 3) points on an arching ribbon leaf from the stem at ``node_z_m``: it rises by about
    ``rise_m``, then droops, and tapers from 6 cm wide to its tip."""
    u = rng.uniform(0.0, 1.0, n)
    across = rng.uniform(-0.5, 0.5, n) * 0.06 * (1.0 - 0.8 * u)
    a = np.radians(azimuth_deg)
    along = np.array([np.cos(a), np.sin(a)])
    side = np.array([-np.sin(a), np.cos(a)])
    xy = np.asarray(foot_xy) + (u * length_m)[:, None] * along + across[:, None] * side
    z = node_z_m + rise_m * np.sin(np.pi * u) - 0.5 * rise_m * u**2
    return np.column_stack([xy, z])


def plant(
    rng: np.random.Generator,
    foot_xy: tuple[float, float],
    leaves: list[tuple[float, float, float, float]],
    stem_height_m: float = 0.35,
    stem_points: int = 3000,
    points_per_leaf: int = 4000,
) -> NDArray[np.float64]:
    """A stem standing at ``foot_xy`` on z = 0 and ``leaves`` (azimuth_deg, node_z_m, length_m,
    rise_m)."""
    parts = [cylinder(rng, foot_xy[0], foot_xy[1], 0.01, stem_height_m, stem_points)]
    for azimuth, node_z, length, rise in leaves:
        parts.append(leaf(rng, foot_xy, azimuth, node_z, length, rise, points_per_leaf))
    return np.concatenate(parts)


def crossing_pair(rng: np.random.Generator) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two plants 0.8 m apart whose long leaves reach across into each other's space, cross in
    side view and touch where they cross (A's leaf along +x, B's along -x, same vertical
    plane)."""
    a = plant(rng, (0.0, 0.0), [(0.0, 0.12, 0.70, 0.20), (180.0, 0.18, 0.45, 0.15)])
    b = plant(rng, (0.8, 0.0), [(180.0, 0.15, 0.70, 0.12), (0.0, 0.22, 0.40, 0.15)])
    return a, b


def level_leaf(
    rng: np.random.Generator,
    foot_xy: tuple[float, float],
    azimuth_deg: float,
    node_z_m: float,
    length_m: float,
    level_z_m: float,
    n: int,
) -> NDArray[np.float64]:
    """(n, 3) points on a ribbon leaf from the stem at ``node_z_m`` that rises over its first
    15 cm to ``level_z_m`` and runs level from there, tapering from 7 cm wide to 2.8 cm at its
    tip."""
    u = rng.uniform(0.0, 1.0, n)
    across = rng.uniform(-0.5, 0.5, n) * 0.07 * (1.0 - 0.6 * u)
    a = np.radians(azimuth_deg)
    along = np.array([np.cos(a), np.sin(a)])
    side = np.array([-np.sin(a), np.cos(a)])
    xy = np.asarray(foot_xy) + (u * length_m)[:, None] * along + across[:, None] * side
    ramp = np.minimum(u * length_m / 0.15, 1.0)
    z = node_z_m + (level_z_m - node_z_m) * (1.0 - (1.0 - ramp) ** 2)
    return np.column_stack([xy, z])


def lying_pair(
    rng: np.random.Generator, gap_m: float = 0.008
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two plants whose leaves touch tangentially: A's long level leaf (along +x from (0, 0))
    lies ``gap_m`` over B's level leaf (B at (0.55, 0.35), its leaf along -y), across it in
    plan view, both surfaces horizontal there (the same normal). B reaches the contact along
    35 cm of leaf, A along 55 cm, and A's outer 20 cm lies beyond the contact, outwards from
    both stems."""
    a = np.concatenate(
        [plant(rng, (0.0, 0.0), []), level_leaf(rng, (0.0, 0.0), 0.0, 0.15, 0.75, 0.30, 6000)]
    )
    b = np.concatenate(
        [
            plant(rng, (0.55, 0.35), []),
            level_leaf(rng, (0.55, 0.35), 270.0, 0.12, 0.55, 0.30 - gap_m, 5000),
        ]
    )
    return a, b


def sloped_leaf(
    rng: np.random.Generator,
    foot_xy: tuple[float, float],
    azimuth_deg: float,
    node_z_m: float,
    length_m: float,
    slope_deg: float,
    n: int,
) -> NDArray[np.float64]:
    """(n, 3) points on a flat ribbon leaf from the stem at ``node_z_m`` rising straight at
    ``slope_deg`` from level, tapering from 7 cm wide to 2.8 cm at its tip."""
    u = rng.uniform(0.0, 1.0, n)
    across = rng.uniform(-0.5, 0.5, n) * 0.07 * (1.0 - 0.6 * u)
    a, slope = np.radians(azimuth_deg), np.radians(slope_deg)
    along = np.array([np.cos(a), np.sin(a)])
    side = np.array([-np.sin(a), np.cos(a)])
    s = u * length_m
    xy = np.asarray(foot_xy) + (s * np.cos(slope))[:, None] * along + across[:, None] * side
    return np.column_stack([xy, node_z_m + s * np.sin(slope)])


def x_pair(
    rng: np.random.Generator, slope_deg: float = 60.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two leaves crossing in an X: A's level leaf (along +x from (0, 0), 30 cm up, 65 cm long)
    runs through B's leaf, which rises at ``slope_deg`` from B's stem at (0.55, 0.10) across
    it (along -y) and crosses it 10 cm from B's stem, 55 cm from A's; A's tip runs on 10 cm
    past the X. The sheets' normals are ``slope_deg`` apart."""
    a = np.concatenate(
        [plant(rng, (0.0, 0.0), []), level_leaf(rng, (0.0, 0.0), 0.0, 0.15, 0.65, 0.30, 7000)]
    )
    to_x = 0.10 / np.cos(np.radians(slope_deg))  # along B's leaf from its stem to A's leaf
    node_z = 0.30 - to_x * np.sin(np.radians(slope_deg))
    b = np.concatenate(
        [
            plant(rng, (0.55, 0.10), []),
            sloped_leaf(rng, (0.55, 0.10), 270.0, node_z, to_x + 0.15, slope_deg, 5000),
        ]
    )
    return a + rng.normal(0.0, 0.001, a.shape), b + rng.normal(0.0, 0.001, b.shape)


def resting_leaf(
    rng: np.random.Generator,
    start_xy: tuple[float, float],
    z_m: float,
    join_m: float,
    turn_deg: float,
    length_m: float,
    n: int,
) -> NDArray[np.float64]:
    """(n, 3) points on a flat leaf at height ``z_m`` that runs along +x from ``start_xy`` for
    ``join_m``, then turns ``turn_deg`` and runs on to ``length_m``, tapering from 6 cm wide."""
    u = rng.uniform(0.0, 1.0, n)
    s = u * length_m
    across = rng.uniform(-0.5, 0.5, n) * 0.06 * (1.0 - 0.6 * u)
    t = np.radians(turn_deg)
    turned = np.array([np.cos(t), np.sin(t)])
    before = s <= join_m
    centre = np.where(
        before[:, None],
        np.column_stack([s, np.zeros(n)]),
        np.array([join_m, 0.0]) + np.outer(s - join_m, turned),
    )
    heading = np.where(before[:, None], [1.0, 0.0], turned)
    side = np.column_stack([-heading[:, 1], heading[:, 0]])
    xy = np.asarray(start_xy) + centre + across[:, None] * side
    return np.column_stack([xy, np.full(n, z_m)])


def stacked_plant(rng: np.random.Generator) -> NDArray[np.float64]:
    """A plant at (0, 0) whose long level leaf (along +x, 75 cm, 30 cm up) carries another
    leaf resting on it 1 cm over and 5 cm to the side from 15 cm out, which leaves it 12 cm
    further on at 60 degrees: one branch for the organ step unsplit, two arms split at their
    fork; the first leaf's trace widens abruptly where the second joins it."""
    return np.concatenate(
        [
            plant(rng, (0.0, 0.0), []),
            level_leaf(rng, (0.0, 0.0), 0.0, 0.15, 0.75, 0.30, 6000),
            resting_leaf(rng, (0.15, 0.05), 0.31, 0.12, 60.0, 0.40, 3000),
        ]
    )


def tapering_leaf(rng: np.random.Generator, n: int = 8000) -> NDArray[np.float64]:
    """(n, 3) points spread evenly on a leaf along +x from the stem at (0, 0): it rises over
    its first 15 cm from 0.15 to 0.30 m and runs level, 7 cm wide out to 55 cm, then narrows
    evenly to 1 cm at its tip (80 cm): the outer part of a broad leaf (the second model's are
    9 cm wide and narrow to 5 within 10 cm)."""
    x = rng.uniform(0.0, 0.8, 3 * n)
    y = rng.uniform(-0.035, 0.035, 3 * n)
    half = np.where(x <= 0.55, 0.035, 0.035 - (x - 0.55) / 0.25 * 0.03)
    kept = np.abs(y) <= half
    x, y = x[kept][:n], y[kept][:n]
    ramp = np.minimum(x / 0.15, 1.0)
    return np.column_stack([x, y, 0.15 + 0.15 * (1.0 - (1.0 - ramp) ** 2)])
