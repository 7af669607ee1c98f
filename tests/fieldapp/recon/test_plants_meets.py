"""A plant whose widest extent meets another plant is said to be maybe wider or narrower than
measured: its width ends where it was cut from the neighbour, not where its leaf was seen to
end (or on a piece of the neighbour)."""

from __future__ import annotations

import numpy as np
import pytest

from fieldapp.recon.plants import search_plants
from fieldapp.recon.settings import PlantSettings, StemSettings

from .synthetic import LEAF_RGB, colored
from .test_plants_stems import NO_SOIL, width_m
from .touching import lying_pair, plant

NO_RIBBONS = PlantSettings(stems=StemSettings(follow_leaves=False))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_plant_cut_where_its_leaf_meets_the_neighbour_is_said_to_meet_it(seed: int) -> None:
    """Without the ribbons B takes A's outer leaf from where the two touch: A ends there, 20 cm
    short of its tip, and is named as meeting B."""
    a, b = lying_pair(np.random.default_rng(seed))
    search = search_plants(colored(np.concatenate([a, b]), LEAF_RGB), NO_SOIL, NO_RIBBONS, 0.15)
    first, second = sorted(search.plants, key=lambda p: p.traits.x_m)
    assert first.traits.width_m < width_m(a) - 0.1  # cut short, as the truth says
    assert search.meets.get(first.id) == second.id
    warning = next(w for w in search.warnings(0.005) if "widest extent meets" in w)
    assert f"{first.id} (plant {second.id})" in warning
    assert "may be wider or narrower than measured" in warning  # it may hold the other's


def test_plants_apart_meet_nothing() -> None:
    rng = np.random.default_rng(0)
    leaves = [(0.0, 0.12, 0.5, 0.15), (180.0, 0.2, 0.45, 0.15)]
    points = np.concatenate([plant(rng, (0.0, 0.0), leaves), plant(rng, (1.5, 0.0), leaves)])
    search = search_plants(colored(points, LEAF_RGB), NO_SOIL, PlantSettings(), 0.15)
    assert len(search.plants) == 2 and search.meets == {} and search.splits == []
