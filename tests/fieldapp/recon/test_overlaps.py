"""Which stations overlap enough to register (``pairwise.overlapping``).

The absolute bar (4 m2 of shared ground) was set on the simulated rig, whose neighbours share
5.4-9 m2; an independent renderer's higher, shallower camera (1.55 m, 37.5 degrees) left its
neighbours 2.9-3.9 m2 and the plot with no pair at all: every station kept its coarse pose.
"""

from __future__ import annotations

import numpy as np

from fieldapp.recon.pairwise import find_overlaps, largest_overlaps, overlapping
from fieldapp.recon.settings import RegistrationSettings

SIDE, DIAGONAL, TWO_APART, OPPOSITE = 3.6, 3.1, 1.6, 0.0
"""Shared ground (m2) of a rig that sees little of it: the renderer's plot's figures."""


def _plan_areas(side: float, diagonal: float, two_apart: float) -> dict[tuple[int, int], float]:
    """Every pair of a 3 x 3 plan of stations 1..9 (row-major) with the area its kind shares."""
    where = {s: divmod(s - 1, 3) for s in range(1, 10)}
    areas = {}
    for a in range(1, 10):
        for b in range(a + 1, 10):
            (ra, ca), (rb, cb) = where[a], where[b]
            steps = sorted((abs(ra - rb), abs(ca - cb)))
            areas[(a, b)] = {
                (0, 1): side,
                (1, 1): diagonal,
                (0, 2): two_apart,
                (1, 2): two_apart / 3,
            }.get((steps[0], steps[1]), OPPOSITE)
    return areas


def _registered(areas: dict[tuple[int, int], float]) -> set[tuple[int, int]]:
    settings, largest = RegistrationSettings(), largest_overlaps(areas)
    return {pair for pair in areas if overlapping(*pair, areas, largest, settings)}


def test_a_rig_that_sees_little_ground_registers_its_neighbours_and_no_more() -> None:
    areas = _plan_areas(SIDE, DIAGONAL, TWO_APART)
    registered = _registered(areas)
    assert registered == {p for p, v in areas.items() if v in (SIDE, DIAGONAL)}
    assert len(registered) == 20  # 12 sides, 8 diagonals, as on the simulated rig


def test_the_simulated_rig_registers_as_before() -> None:
    """Neighbours over the absolute bar; stations two apart (1.7-3.2 m2, at most 0.36 of the
    largest overlaps) never."""
    areas = _plan_areas(9.0, 5.4, 3.2)
    assert _registered(areas) == {p for p, v in areas.items() if v >= 4.0}


def test_a_thin_lens_alone_is_not_an_overlap() -> None:
    """With no real neighbour, a station's largest overlap is a lens under the floor (1 m2)."""
    areas = {(1, 2): 0.8, (1, 3): 0.5, (2, 3): 0.0}
    assert _registered(areas) == set()


def test_find_overlaps_takes_the_pairs_sharing_a_share_of_the_largest_overlaps() -> None:
    """Three stations in a line 1.4 m apart, each seeing a 2.2 m square of ground: neighbours
    share 0.8 x 2.2 m (1.76 m2, under the absolute bar), the two ends nothing."""
    rng = np.random.default_rng(0)
    stations = {}
    for station, x0 in ((1, 0.0), (2, 1.4), (3, 2.8)):
        xy = rng.uniform(0.0, 2.2, (60000, 2)) + np.array([x0, 0.0])
        stations[station] = np.column_stack([xy, rng.normal(0.0, 0.002, len(xy))])
    pairs = [(o.a, o.b) for o in find_overlaps(stations, RegistrationSettings())]
    assert pairs == [(1, 2), (2, 3)]
    strict = RegistrationSettings(min_overlap_share=1.0)
    assert [(o.a, o.b) for o in find_overlaps(stations, strict)] == [(1, 2), (2, 3)]
    absolute_only = RegistrationSettings(min_overlap_floor_m2=2.0)
    assert find_overlaps(stations, absolute_only) == []
