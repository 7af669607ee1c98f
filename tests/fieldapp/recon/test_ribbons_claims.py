"""What a ribbon's claim brings with it: a channelled leaf's edges and the points its steps
missed (an independent renderer's plain touching plot: the neighbour kept a V-folded leaf's
edges and points scattered along it, and came out 35 cm too wide; 26 cm now, by three points
no ribbon reaches)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from fieldapp.recon.ribbons import Ribbon, _with_strays, follow

NORMAL = np.array([0.0, 0.0, 1.0])


def sheet(
    x: tuple[float, float], y: tuple[float, float], z: float, rng: np.random.Generator
) -> NDArray[np.float64]:
    """A level sheet of points 3 mm apart, jittered by 0.5 mm."""
    gx, gy = np.meshgrid(np.arange(*x, 0.003), np.arange(*y, 0.003), indexing="ij")
    points = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
    return points + rng.normal(0.0, 0.0005, points.shape)


def straight_ribbon(width_m: float = 0.05) -> Ribbon:
    """A level ribbon traced along x up to the origin, 50 cm up."""
    arc = np.arange(0.0, 0.2, 0.01)
    centres = np.column_stack([arc - arc[-1], np.zeros_like(arc), np.full_like(arc, 0.5)])
    return Ribbon(centres, arc.copy(), np.full(len(arc), width_m), NORMAL.copy())


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_ribbon_takes_the_raised_edges_of_a_channelled_leaf_wider_than_itself(
    seed: int,
) -> None:
    """The leaf runs on 8 cm wide, its section a channel (edges 1 cm above its middle), where
    the ribbon is 5 cm wide: its steps take the middle, and the edges too, as far as the
    surface runs on without a gap (without them 1-20 % of the edges). A neighbour's leaf
    beside it past a 1.1 cm gap, and one beside it 2 cm under the channel's line, are not
    taken."""
    rng = np.random.default_rng(seed)
    leaf = sheet((0.005, 0.15), (-0.04, 0.04), 0.5, rng)
    leaf[:, 2] += 6.0 * leaf[:, 1] ** 2  # 1 cm up at the edges, 0.5 cm at the ribbon's
    rim = 0.5 + 6.0 * 0.04**2
    apart = sheet((0.005, 0.15), (0.051, 0.1), rim, rng)
    under = sheet((0.005, 0.15), (-0.09, -0.041), rim - 0.02, rng)
    points = np.vstack([leaf, apart, under])
    taken, _ = follow(straight_ribbon(), points, cKDTree(points), np.ones(len(points), bool))
    got = np.zeros(len(points), dtype=bool)
    got[taken] = True
    edges = np.abs(leaf[:, 1]) > 0.03  # past the ribbon's half width and its 5 mm margin
    assert got[: len(leaf)][edges].mean() > 0.85
    assert got[: len(leaf)].mean() > 0.9
    assert not got[len(leaf) :].any()


def test_the_points_a_ribbon_missed_among_those_it_took_go_with_them() -> None:
    """A ribbon took 85 % of a leaf's points from plant 0, at random (its 1 cm slabs across a
    curving leaf): the rest go to plant 1 too. Plant 0's own leaf beside it, and its leaf
    lying 8 mm under the taken one, stay plant 0's."""
    rng = np.random.default_rng(1)
    taken_leaf = sheet((0.1, 0.3), (0.0, 0.08), 0.5, rng)
    beside = sheet((-0.1, 0.1), (0.0, 0.08), 0.5, rng)  # meets it along x = 0.1
    under = sheet((0.1, 0.3), (0.0, 0.08), 0.492, rng)
    points = np.vstack([taken_leaf, beside, under])
    labels = np.zeros(len(points), dtype=np.intp)
    won = np.flatnonzero(rng.random(len(taken_leaf)) < 0.85)
    labels[won] = 1
    everyone = np.ones(len(points), dtype=bool)
    moved = _with_strays(points, cKDTree(points), labels, won, everyone, everyone)
    inner = taken_leaf[:, 0] > 0.11  # on the line where they meet, half of each side's
    assert (labels[: len(taken_leaf)][inner] == 1).all()
    assert (labels[len(taken_leaf) :] == 0).all()
    assert set(moved.tolist()) <= set(range(len(taken_leaf)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_ribbon_run_on_along_a_neighbour_s_held_leaf_does_not_take_its_tip(seed: int) -> None:
    """The leaf ends where the ribbon was traced to, lying on its neighbour's leaf: the ribbon
    runs on along that leaf (held: traced, so none of it changes hands) and 17 cm on meets four
    of the neighbour's points past where its leaf is held. A step filled only by the held leaf
    is not this leaf's: the four stay (a touching plot's p11 took them, 11 cm past its own
    points). Without the held points marked, the steps they fill take them."""
    rng = np.random.default_rng(seed)
    held_leaf = sheet((0.005, 0.2), (-0.02, 0.02), 0.5, rng)
    tip = np.column_stack(
        [rng.uniform(0.165, 0.175, 4), rng.uniform(-0.01, 0.01, 4), np.full(4, 0.5)]
    )
    points = np.vstack([held_leaf, tip])
    held = np.zeros(len(points), dtype=bool)
    held[: len(held_leaf)] = True
    claimable = ~held
    tree = cKDTree(points)
    taken, _ = follow(straight_ribbon(0.04), points, tree, claimable, held)
    assert len(taken) == 0
    taken, _ = follow(straight_ribbon(0.04), points, tree, claimable)
    assert set(taken.tolist()) == set(range(len(held_leaf), len(points)))
