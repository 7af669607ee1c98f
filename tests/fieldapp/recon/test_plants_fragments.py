"""Points no stem reaches along the plant (a leaf seen with a gap at its base) go to the nearest
plant of their density cluster; where that cluster holds two plants, the join is a guess and
says so: the joined points a second plant lies nearly as near to are ambiguous, and flag the
plant that took them."""

from __future__ import annotations

import numpy as np

from fieldapp.recon.geodesic import UNREACHED
from fieldapp.recon.plants import _join_fragments

VOXEL_M = 0.025
MARGIN_M = 0.15


def _line(x0: float, x1: float, y: float = 0.0) -> np.ndarray:
    """Points every 5 mm along x from ``x0`` to ``x1``, 20 cm up."""
    x = np.arange(x0, x1 + 1e-9, 0.005)
    return np.column_stack([x, np.full_like(x, y), np.full_like(x, 0.2)])


def _joined(parts: list[tuple[np.ndarray, int]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    points = np.concatenate([p for p, _ in parts])
    labels = np.concatenate([np.full(len(p), label) for p, label in parts]).astype(np.intp)
    merges: list[str] = []
    guessed, _ = _join_fragments(points, labels, VOXEL_M, MARGIN_M, merges)
    assert merges and "joined to the nearest plant" in merges[0]
    return points, labels, guessed


def test_a_fragment_between_two_plants_goes_to_the_nearer_as_a_guess() -> None:
    """Plant 0's leaf ends at x = 0.40 m, plant 1's at 0.60; the fragment between them (a leaf
    cut off from its base) touches both: each point goes to the nearer, and is a guess where
    the other lies less than the margin farther."""
    # the plants' leaves long enough that the fragment's halves are under 5 % of either
    # (JOINED_SHARE: more, and every joined point of the plant would count ambiguous)
    a, b, fragment = _line(-2.0, 0.40), _line(0.60, 3.0), _line(0.412, 0.59)  # no tie
    _, labels, guessed = _joined([(a, 0), (b, 1), (fragment, UNREACHED)])
    part = slice(len(a) + len(b), None)
    x = fragment[:, 0]
    np.testing.assert_array_equal(labels[part], np.where(x < 0.5, 0, 1))
    d_a, d_b = x - 0.40, 0.60 - x
    np.testing.assert_array_equal(guessed[part], np.abs(d_a - d_b) < MARGIN_M)
    assert guessed[part].any() and not guessed[part].all()  # the ends are sure, the middle not
    assert not guessed[: len(a) + len(b)].any()  # points reached along a plant are not touched


def test_a_fragment_beside_one_plant_of_a_shared_cluster_is_sure() -> None:
    """Plants 0 and 1 in one cluster (their leaves meet at x = 0.5 m), a fragment 1 cm past
    the far end of plant 0's other leaf: plant 1 is more than the margin farther."""
    a, b = _line(-0.40, 0.50), _line(0.505, 1.0)
    fragment = _line(-0.45, -0.41)  # 5 % of plant 0: a tip, not a part of it (JOINED_SHARE)
    _, labels, guessed = _joined([(a, 0), (b, 1), (fragment, UNREACHED)])
    part = slice(len(a) + len(b), None)
    assert (labels[part] == 0).all() and not guessed.any()


def test_a_fragment_in_a_cluster_of_one_plant_is_sure_whatever_lies_beyond() -> None:
    """The seedling case: plant 1 is in a cluster of its own, 12 cm from the fragment (within
    the margin, but across air): the fragment is plant 0's without doubt."""
    a, fragment, b = _line(0.0, 0.40), _line(0.41, 0.48), _line(0.60, 1.0)
    _, labels, guessed = _joined([(a, 0), (b, 1), (fragment, UNREACHED)])
    part = slice(len(a) + len(b), None)
    assert (labels[part] == 0).all() and not guessed.any()


def test_another_stem_across_air_does_not_make_a_join_a_guess() -> None:
    """Plants 0 and 1 share a cluster (their leaves meet at x = 0.40 m), as do plants 2 and 3,
    6 cm away across air; the fragment beyond plant 0's other end lies 6 cm from plant 2, but
    in plant 0's cluster the only other plant is 45-60 cm farther: the join is sure."""
    a, b = _line(0.0, 0.40), _line(0.405, 0.8)
    c, d = _line(-0.2, -0.01, y=0.06), _line(0.0, 0.3, y=0.06)
    fragment = _line(-0.025, -0.01)  # under 5 % of plant 0 (JOINED_SHARE)
    _, labels, guessed = _joined([(a, 0), (b, 1), (c, 2), (d, 3), (fragment, UNREACHED)])
    assert (labels[-len(fragment) :] == 0).all() and not guessed.any()


def test_a_plant_that_took_a_large_part_of_a_shared_canopy_so_is_flagged() -> None:
    """Plants 0 and 1 share a cluster; a stretch past plant 1's far end that no stem reached
    (its own plant's body cut from its stem, say) goes to plant 1, plant 0 far beyond the
    margin, so no single point is a guess; but a quarter of plant 1 is then points no stem
    reached (JOINED_SHARE): all of them are counted ambiguous, so that it is flagged. With
    no other plant in the cluster the same stretch is plant 1's without doubt."""
    a, b, stretch = _line(0.0, 0.30), _line(0.305, 1.5), _line(1.505, 1.9)
    merges: list[str] = []
    points = np.concatenate([a, b, stretch])
    labels = np.repeat([0, 1, UNREACHED], [len(a), len(b), len(stretch)]).astype(np.intp)
    guessed, _ = _join_fragments(points, labels, VOXEL_M, MARGIN_M, merges)
    part = slice(len(a) + len(b), None)
    assert (labels[part] == 1).all() and guessed[part].all()
    assert not guessed[: len(a) + len(b)].any()  # points reached along a plant are not touched
    assert any("1 plants with more than 5 % of their points joined" in m for m in merges)
    alone = np.concatenate([b, stretch])
    labels = np.repeat([1, UNREACHED], [len(b), len(stretch)]).astype(np.intp)
    guessed, _ = _join_fragments(alone, labels, VOXEL_M, MARGIN_M, [])
    assert (labels == 1).all() and not guessed.any()
