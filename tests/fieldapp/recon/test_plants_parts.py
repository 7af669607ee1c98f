"""Small groups no stem reaches are parts of plants, not plants (``plants._parts_seen_apart``).

On an independent renderer's touching plots (80 cm grid and denser), five of eight plots had
"plants" of 207-957 points, 12-40 cm tall and off the planting grid: the outer parts of leaves
whose middle no camera saw, cut off from their plants by the gap, and, on two plots, soil
lifted into the plants beside a pale straw (weakly green) by the leaves' rim rules. The plants
found from stems there held 10 000-30 000 points each; plants whose stem was not seen (a
plot's edge) 2 600-19 000.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.plants import PlantSearch, search_plants
from fieldapp.recon.settings import PlantSettings
from fieldapp.recon.traits import smallest_enclosing_circle

from .synthetic import LEAF_RGB, SOIL_RGB, colored, ground_patch
from .touching import leaf, plant

FEET = [(0.0, 0.0), (0.8, 0.0), (0.0, 0.8), (0.8, 0.8)]


def _leaf_with_gap(rng: np.random.Generator) -> tuple[NDArray, NDArray]:
    """A 60 cm leaf of the plant at (0, 0) pointing out of the plot (-y), node at 30 cm: its
    inner half and its outer fifth, the stretch between them (12 cm) unseen."""
    points = leaf(rng, (0.0, 0.0), -90.0, 0.30, 0.60, 0.15, 5000)
    reach = -points[:, 1] / 0.60
    return points[reach < 0.5], points[reach > 0.8]


def _plot(rng: np.random.Generator, *extra: Cloud) -> tuple[Cloud, NDArray]:
    """Four plants on an 80 cm grid, each a stem and two leaves along the row (x), plus
    ``extra``; and the first plant's own points (at (0, 0), without ``extra``)."""
    clouds = [
        colored(plant(rng, foot, [(0.0, 0.15, 0.3, 0.1), (180.0, 0.2, 0.3, 0.1)]), LEAF_RGB)
        for foot in FEET
    ]
    first = clouds[0].points
    clouds.extend(extra)
    cloud = Cloud(
        np.concatenate([c.points for c in clouds]), np.concatenate([c.colors for c in clouds])
    )
    return cloud, first


def _search(cloud: Cloud, rng: np.random.Generator) -> PlantSearch:
    soil = ground_patch(rng, 1.6, 40000)
    soil[:, :2] += 0.4
    return search_plants(cloud, soil, PlantSettings(), 0.3)


def _at(search: PlantSearch, xy: tuple[float, float]) -> list:
    return [p for p in search.plants if np.hypot(p.traits.x_m - xy[0], p.traits.y_m - xy[1]) < 0.05]


def test_a_leaf_part_seen_apart_joins_its_plant_and_is_a_guess() -> None:
    rng = np.random.default_rng(0)
    inner, outer = _leaf_with_gap(rng)
    cloud, own = _plot(rng, colored(inner, LEAF_RGB), colored(outer, LEAF_RGB))
    search = _search(cloud, rng)
    assert len(search.plants) == 4  # the outer part is no fifth plant
    (first,) = _at(search, (0.0, 0.0))
    assert np.sum(first.cloud.points[:, 1] < -0.45) == len(outer)  # it holds the whole part
    truth = 2.0 * smallest_enclosing_circle(np.concatenate([own, inner, outer])[:, :2]).radius_m
    assert first.traits.width_m == pytest.approx(truth, abs=0.005)
    assert first.ambiguous_share * len(first.cloud) >= len(outer) - 0.5  # and says it guessed
    assert any("seen apart" in m and "joined" in m for m in search.merges)


def test_a_part_far_from_every_plant_is_not_counted() -> None:
    """Beyond :data:`~fieldapp.recon.plants.PART_REACH_M` of every plant's points."""
    rng = np.random.default_rng(1)
    _, outer = _leaf_with_gap(rng)
    outer[:, 1] -= 0.4  # 0.88-1.0 m out, 58 cm past the leaf's inner half
    search = _search(_plot(rng, colored(outer, LEAF_RGB))[0], rng)
    assert len(search.plants) == 4
    assert all(p.cloud.points[:, 1].min() > -0.8 for p in search.plants)  # given to none
    assert any("seen apart" in m and "not counted" in m for m in search.merges)


def _lifted_soil(rng: np.random.Generator, n: int = 600) -> Cloud:
    """Soil 2-5 cm up on a 18 x 6 cm rise at (0.4, 0.4), a few pale-straw points in it: what
    the leaves' rim rules lift into the plants beside a straw."""
    xy = np.array([0.4, 0.4]) + rng.uniform([-0.09, -0.03], [0.09, 0.03], (n, 2))
    points = np.column_stack([xy, rng.uniform(0.02, 0.05, n)])
    colors = np.tile(np.array(SOIL_RGB, np.uint8), (n, 1))
    colors[: n // 10] = (190, 175, 115)
    return Cloud(points, colors)


def test_a_small_group_of_soil_coloured_points_is_not_a_plant() -> None:
    rng = np.random.default_rng(2)
    search = _search(_plot(rng, _lifted_soil(rng))[0], rng)
    assert len(search.plants) == 4
    assert any("not green" in m for m in search.merges)


def _low_seedling(rng: np.random.Generator, n: int = 600) -> Cloud:
    """A late seedling with no stem to find: a tuft of leaf 1-7 cm up at (0.4, 0.4)."""
    xy = np.array([0.4, 0.4]) + rng.uniform(-0.04, 0.04, (n, 2))
    return colored(np.column_stack([xy, rng.uniform(0.01, 0.07, n)]), LEAF_RGB)


def _plant_without_its_foot(rng: np.random.Generator) -> Cloud:
    """A plant at (0.4, 0.4) whose lower 15 cm no camera saw (a plot's edge)."""
    points = plant(rng, (0.4, 0.4), [(45.0, 0.2, 0.3, 0.1), (225.0, 0.25, 0.3, 0.1)])
    return colored(points[points[:, 2] > 0.15], LEAF_RGB)


def test_a_small_green_group_on_the_soil_and_a_large_one_up_there_stay_plants() -> None:
    """Neither is a part: the first may be a late seedling, the second holds a plant's share
    of points."""
    for make in (_low_seedling, _plant_without_its_foot):
        rng = np.random.default_rng(3)
        search = _search(_plot(rng, make(rng))[0], rng)
        assert len(search.plants) == 5, make.__name__
        assert _at(search, (0.4, 0.4)), make.__name__
        assert not any("seen apart" in m or "not green" in m for m in search.merges)


def test_without_enough_plants_from_stems_nothing_is_judged_small() -> None:
    """With fewer than three plants found from stems there is no typical plant to judge by."""
    rng = np.random.default_rng(4)
    inner, outer = _leaf_with_gap(rng)
    one = colored(plant(rng, (0.0, 0.0), [(0.0, 0.15, 0.3, 0.1)]), LEAF_RGB)
    parts = [one, colored(inner, LEAF_RGB), colored(outer, LEAF_RGB)]
    cloud = Cloud(
        np.concatenate([c.points for c in parts]), np.concatenate([c.colors for c in parts])
    )
    search = _search(cloud, rng)
    assert len(search.plants) == 2
