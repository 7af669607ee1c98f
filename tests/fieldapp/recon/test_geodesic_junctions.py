"""A stem's own paths step across the gaps near it (``geodesic.Junctions``).

An independent renderer's 80 cm plots lost whole leaves to neighbours: the cameras saw the stem
from one side and the leaf's base not whole, so in the plant graph (steps of 1.5 cm at most)
the leaf was cut from its stem 3 cm off it, and the only way to it was the neighbour's, across
the contact where the neighbour's drooping leaf touched it (seed 14's plant 31: a 57 cm leaf,
30 cm too narrow, its neighbour 15.5 cm too wide). Near its own stem, a plant's paths may now
step across gaps of up to 4 cm, at the price of the sharpest bend.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.plants import assign_by_settings, search_plants
from fieldapp.recon.settings import PlantSettings, StemSettings

from .synthetic import LEAF_RGB, ground_patch
from .touching import leaf, level_leaf, plant

OFF = StemSettings(junction_radius_m=0.0)


def _cut_leaf_and_a_drooping_neighbour(
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Plant A's stem at (0, 0) and its level leaf along +x (75 cm, 30 cm up), none of it
    within 3.5 cm of the stem's axis (a 2.5 cm gap at its base); plant B at (0.5, 0.6), whose
    60 cm leaf droops onto A's leaf from the side, 50 cm out from A's stem, its tip steep
    against A's level surface."""
    a_stem = plant(rng, (0.0, 0.0), [])
    a_leaf = level_leaf(rng, (0.0, 0.0), 0.0, 0.15, 0.75, 0.30, 7000)
    a_leaf = a_leaf[np.hypot(a_leaf[:, 0], a_leaf[:, 1]) >= 0.035]
    b = np.concatenate(
        [
            plant(rng, (0.5, 0.6), [], stem_height_m=0.5),
            leaf(rng, (0.5, 0.6), 270.0, 0.46, 0.6, 0.3, 5000),
        ]
    )
    return a_stem, a_leaf, b


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_a_leaf_cut_from_its_stem_stays_with_it_across_the_gap(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a_stem, a_leaf, b = _cut_leaf_and_a_drooping_neighbour(rng)
    points = np.concatenate([a_stem, a_leaf, b])
    points += rng.normal(0.0, 0.001, points.shape)
    feet = np.array([(0.0, 0.0), (0.5, 0.6)])
    on_leaf = slice(len(a_stem), len(a_stem) + len(a_leaf))
    on_b = slice(len(a_stem) + len(a_leaf), None)
    stem = assign_by_settings(points, feet, StemSettings()).stem
    assert np.mean(stem[on_leaf] == 0) > 0.99
    assert np.mean(stem[on_b] == 1) > 0.9  # the neighbour keeps its own leaf
    # the control: without the steps the neighbour takes the leaf across the contact
    stem = assign_by_settings(points, feet, OFF).stem
    assert np.mean(stem[on_leaf] == 1) > 0.99


def test_the_plant_with_the_cut_leaf_is_measured_whole() -> None:
    rng = np.random.default_rng(0)
    a_stem, a_leaf, b = _cut_leaf_and_a_drooping_neighbour(rng)
    points = np.concatenate([a_stem, a_leaf, b])
    cloud = Cloud(points, np.tile(np.array(LEAF_RGB, np.uint8), (len(points), 1)))
    soil = ground_patch(rng, 1.5, 30000)
    widths = []
    for stems in (StemSettings(), OFF):
        plants = search_plants(cloud, soil, PlantSettings(stems=stems), 0.3).plants
        assert len(plants) == 2
        a = min(plants, key=lambda p: np.hypot(p.traits.x_m, p.traits.y_m))
        widths.append(a.traits.width_m)
    assert widths[0] > 0.7  # stem to tip, 75 cm
    assert widths[1] < 0.1  # its stem alone


def test_a_neighbour_s_tip_passing_by_a_stem_stays_with_the_neighbour() -> None:
    """The price of a step across a gap is the sharpest bend's: plant B's 72 cm leaf ends 3 cm
    from plant A's stem (2 cm from its surface), 25-35 cm up, touching nothing; A's way to it
    across the gap (its stem, the step and the price) is longer than B's along its leaf."""
    rng = np.random.default_rng(5)
    a = plant(rng, (0.0, 0.0), [(180.0, 0.2, 0.4, 0.1)], stem_height_m=0.5)
    b = plant(rng, (0.75, 0.0), [(180.0, 0.3, 0.72, 0.1)])
    points = np.concatenate([a, b])
    stem = assign_by_settings(points, np.array([(0.0, 0.0), (0.75, 0.0)]), StemSettings()).stem
    assert np.all(stem[: len(a)] == 0)
    assert np.all(stem[len(a) :] == 1)
