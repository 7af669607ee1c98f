"""The outward cost of the geodesic assignment: steps back towards the stem pay, except within
the stem's own column."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import csr_matrix

from fieldapp.recon.geodesic import _outward


def _chain(centres_m: np.ndarray) -> csr_matrix:
    """Each centre joined to the next, both ways, at their distance."""
    n = len(centres_m)
    rows = np.r_[np.arange(n - 1), np.arange(1, n)]
    cols = np.r_[np.arange(1, n), np.arange(n - 1)]
    return csr_matrix((np.linalg.norm(centres_m[rows] - centres_m[cols], axis=1), (rows, cols)))


def _climb() -> np.ndarray:
    """A path up a stem standing at the origin: voxel centroids 1 cm apart in height, 2 and 6
    mm off the stem's axis in turn, either side (what the centroids of a 1 cm stem's voxels
    do)."""
    z = np.arange(20) * 0.01
    x = np.where(np.arange(20) % 2 == 0, 0.002, -0.006)
    return np.column_stack([x, np.zeros(20), z])


def test_a_climb_up_the_stem_costs_its_length_within_the_column() -> None:
    centres = _climb()
    edges = _chain(centres)
    outward = _outward(edges, centres, np.zeros(2), 10.0, column_m=0.03)
    assert outward.data == pytest.approx(edges.data)


def test_without_the_column_the_climb_pays_for_its_zig_zag() -> None:
    """The control: every other step up is 4 mm inwards, 4 cm at 10 x, as long again as the
    climb's 19 steps up (the way down the same)."""
    centres = _climb()
    edges = _chain(centres)
    extra = _outward(edges, centres, np.zeros(2), 10.0).sum() - edges.sum()
    assert extra == pytest.approx(19 * 10.0 * 0.004)


def test_a_step_towards_the_stem_outside_the_column_pays_for_every_centimetre() -> None:
    """A leaf followed back towards the stem from 50 to 40 cm: 10 cm inwards at 10 x."""
    centres = np.array([[0.5, 0.0, 0.3], [0.4, 0.0, 0.3]])
    edges = _chain(centres)
    outward = _outward(edges, centres, np.zeros(2), 10.0, column_m=0.03)
    assert outward[1, 0] == pytest.approx(0.1)  # outwards: its length
    assert outward[0, 1] == pytest.approx(0.1 + 10.0 * 0.1)  # inwards
