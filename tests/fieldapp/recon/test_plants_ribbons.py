"""Leaves followed across contacts: a leaf lying on a neighbour's leaf, the two surfaces with
the same normal (no graph cost sees the contact), keeps its outer part."""

from __future__ import annotations

import numpy as np
import pytest

from fieldapp.recon.plants import search_plants
from fieldapp.recon.ribbons import trace_leaf
from fieldapp.recon.settings import PlantSettings, StemSettings

from .synthetic import LEAF_RGB, colored
from .test_plants_stems import NO_SOIL, own_share, width_m
from .touching import crossing_pair, level_leaf, lying_pair


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_leaf_lying_on_the_neighbours_leaf_keeps_its_outer_part(seed: int) -> None:
    a, b = lying_pair(np.random.default_rng(seed))
    cloud = colored(np.concatenate([a, b]), LEAF_RGB)
    search = search_plants(cloud, NO_SOIL, PlantSettings(), 0.15)
    first, second = sorted(search.plants, key=lambda p: p.traits.x_m)
    assert first.traits.width_m == pytest.approx(width_m(a), abs=0.06)
    assert second.traits.width_m == pytest.approx(width_m(b), abs=0.01)
    assert own_share(first.cloud, a) > 0.9 and own_share(second.cloud, b) > 0.9
    assert any("leaf that runs on" in m for m in search.merges)  # said in report.json


def test_without_the_ribbons_the_neighbour_takes_the_outer_part() -> None:
    """The reason for the ribbons: B reaches the contact along 35 cm of leaf, A along 55 cm,
    and A's tip beyond it runs outwards from both stems; the normals agree at the contact, so
    neither the outward nor the bend cost helps."""
    a, b = lying_pair(np.random.default_rng(0))
    settings = PlantSettings(stems=StemSettings(follow_leaves=False))
    search = search_plants(colored(np.concatenate([a, b]), LEAF_RGB), NO_SOIL, settings, 0.15)
    first = min(search.plants, key=lambda p: p.traits.x_m)
    assert first.traits.width_m < width_m(a) - 0.2


def test_the_leaves_are_followed_whatever_the_reports_flag() -> None:
    """Every plant with an ambiguous point has its leaves followed, not only the plants the
    report flags: on a touching plot a plant's ambiguous share slipped under the flag (0.5 %)
    with a small change of the bend cost, and its ribbon, and the outer part of its leaf, went
    with it (docs/notes/touching-canopies.md, seed 4 p02)."""
    a, b = lying_pair(np.random.default_rng(0))
    settings = PlantSettings(stems=StemSettings(flag_ambiguous_share=0.5))
    search = search_plants(colored(np.concatenate([a, b]), LEAF_RGB), NO_SOIL, settings, 0.15)
    first = min(search.plants, key=lambda p: p.traits.x_m)
    assert first.ambiguous_share < 0.5  # not flagged
    assert first.traits.width_m == pytest.approx(width_m(a), abs=0.06)


def test_a_traced_leaf_stops_where_it_meets_another_plant() -> None:
    rng = np.random.default_rng(4)
    points = level_leaf(rng, (0.0, 0.0), 0.0, 0.15, 0.75, 0.30, 6000)
    touching = points[:, 0] > 0.5  # another plant's points near the leaf from 50 cm on
    found = trace_leaf(points, touching, np.zeros(2))
    assert found is not None
    ribbon, held = found
    assert 0.47 <= ribbon.centres_m[-1, 0] <= 0.5
    # held: the traced part up to 12 cm before its end (where the ribbon's fit rests)
    assert held[points[:, 0] < 0.33].all() and not held[points[:, 0] > 0.4].any()
    assert np.median(ribbon.widths_m[-5:]) == pytest.approx(0.07 * (1 - 0.6 * 0.63), abs=0.01)
    centre, direction, width = ribbon.predict(0.1)  # the level ribbon continues level, tapering
    assert centre == pytest.approx([0.59, 0.0, 0.30], abs=0.01)
    assert abs(direction[0]) > 0.99 and width < ribbon.widths_m[-1]


def test_the_ribbons_also_keep_a_crossing_leaf_without_the_outward_cost() -> None:
    """Where the outward cost is off, A's leaf tip past B's crossing leaf goes to B by path
    length (test_plants_stems.py); its ribbon follows it on across the crossing."""
    a, b = crossing_pair(np.random.default_rng(0))
    settings = PlantSettings(stems=StemSettings(inward_penalty=0.0, bend_penalty_m=0.0))
    search = search_plants(colored(np.concatenate([a, b]), LEAF_RGB), NO_SOIL, settings, 0.15)
    assert search.plants[0].traits.width_m == pytest.approx(width_m(a), abs=0.02)
