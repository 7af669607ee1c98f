"""Plant identity by position: one-to-one, bounded, new plants unmatched."""

from __future__ import annotations

import numpy as np
import pytest

from fieldapp.results.identity import match_positions


def test_shuffled_and_moved_plants_find_themselves():
    rng = np.random.default_rng(1)
    known = rng.uniform(-2, 2, (20, 2))
    order = rng.permutation(20)
    observed = known[order] + rng.normal(0, 0.01, (20, 2))
    assert match_positions(known, observed, 0.15) == [int(i) for i in order]


def test_beyond_the_bound_is_a_new_plant():
    known = np.array([[0.0, 0.0], [0.8, 0.0]])
    observed = np.array([[0.79, 0.02], [0.0, 0.5]])
    assert match_positions(known, observed, 0.15) == [1, None]


def test_one_to_one_even_when_both_are_nearest_to_one_plant():
    known = np.array([[0.0, 0.0], [0.2, 0.0]])
    observed = np.array([[0.05, 0.0], [0.08, 0.0]])
    # greedy nearest would give both to plant 0; the assignment keeps them apart
    assert sorted(m for m in match_positions(known, observed, 0.15) if m is not None) == [0, 1]


def test_the_assignment_prefers_more_pairs_within_the_bound():
    known = np.array([[0.0, 0.0], [0.3, 0.0]])
    observed = np.array([[0.14, 0.0], [0.44, 0.0]])
    # pairing 0-1 (0.16) would be outside; 0->0 (0.14) and 1->1 (0.14) are both inside
    assert match_positions(known, observed, 0.15) == [0, 1]


def test_empty_sides_and_bad_bound():
    assert match_positions(np.zeros((0, 2)), np.ones((2, 2)), 0.1) == [None, None]
    assert match_positions(np.ones((2, 2)), np.zeros((0, 2)), 0.1) == []
    with pytest.raises(ValueError, match="positive"):
        match_positions(np.ones((1, 2)), np.ones((1, 2)), 0.0)
