"""Plants from their stems: touching canopies split along the plants, the grid prior, honesty."""

from __future__ import annotations

import numpy as np
import pytest

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.grid import grid_nodes, stems_at_empty_nodes
from fieldapp.recon.plants import search_plants, voxel_components
from fieldapp.recon.settings import PlantSettings, StemSettings
from fieldapp.recon.stems import find_stems
from fieldapp.recon.traits import smallest_enclosing_circle

from .synthetic import LEAF_RGB, colored, cylinder, ground_patch
from .touching import crossing_pair, leaf, plant

NO_SOIL = np.zeros((0, 3))


def width_m(points: np.ndarray) -> float:
    return 2.0 * smallest_enclosing_circle(points[:, :2]).radius_m


def own_share(found: Cloud, own: np.ndarray) -> float:
    """Share of ``own`` points (a plant's true points) that ``found`` holds."""
    mine = {tuple(p) for p in np.round(own, 9)}
    return sum(tuple(p) in mine for p in np.round(found.points, 9)) / len(own)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_leaves_reaching_across_stay_with_the_stem_they_grow_from(seed: int) -> None:
    a, b = crossing_pair(np.random.default_rng(seed))
    points = np.concatenate([a, b])
    assert len(np.unique(voxel_components(points, 0.025))) == 1  # density clustering: one plant
    search = search_plants(colored(points, LEAF_RGB), NO_SOIL, PlantSettings(), 0.15)
    assert [p.id for p in search.plants] == [1, 2]
    first, second = search.plants
    assert abs(first.traits.x_m) < 0.01 and abs(second.traits.x_m - 0.8) < 0.01
    assert first.traits.width_m == pytest.approx(width_m(a), abs=0.005)
    assert second.traits.width_m == pytest.approx(width_m(b), abs=0.005)
    assert own_share(first.cloud, a) > 0.9 and own_share(second.cloud, b) > 0.9
    assert first.from_stem and second.from_stem
    assert search.splits == [[1, 2]]  # listed for report.json


def test_without_the_outward_cost_the_crossing_leaf_follows_the_neighbour() -> None:
    """The reason for the outward cost: by path length alone A's leaf tip, which lies past B's
    stem's leaf crossing, is nearer to B (with the ribbons off: they follow A's leaf on across
    the crossing, test_plants_ribbons.py)."""
    a, b = crossing_pair(np.random.default_rng(0))
    stems = StemSettings(inward_penalty=0.0, bend_penalty_m=0.0, follow_leaves=False)
    settings = PlantSettings(stems=stems)
    search = search_plants(colored(np.concatenate([a, b]), LEAF_RGB), NO_SOIL, settings, 0.15)
    assert search.plants[0].traits.width_m < width_m(a) - 0.1


def test_stem_feet_are_found_on_uneven_ground_and_leaf_tips_on_the_soil_are_not_stems() -> None:
    rng = np.random.default_rng(3)
    soil = ground_patch(rng, 1.0, 20000)
    soil[:, 2] += 0.03 * soil[:, 0]  # a 3 % slope: the band follows the local ground
    plants = []
    for x in (-0.4, 0.4):
        one = plant(rng, (x, 0.0), [(90.0, 0.10, 0.5, 0.1)])
        one[:, 2] += 0.03 * x
        plants.append(one)
    tip = leaf(rng, (0.2, 0.5), 0.0, 0.02, 0.3, 0.0, 2000)  # a leaf lying flat on the soil
    tip[:, 2] = 0.03 * tip[:, 0] + 0.012
    stems, _ = find_stems(np.concatenate([*plants, tip]), soil, StemSettings())
    xs = sorted(float(s.xy_m[0]) for s in stems)
    assert len(stems) == 2 and abs(xs[0] + 0.4) < 0.01 and abs(xs[1] - 0.4) < 0.01
    assert all(abs(s.ground_z_m - 0.03 * s.xy_m[0]) < 0.005 for s in stems)


def test_where_no_stem_is_seen_density_clusters_are_the_fallback() -> None:
    rng = np.random.default_rng(4)
    with_stem = plant(rng, (0.0, 0.0), [(0.0, 0.12, 0.3, 0.1)])
    floating = leaf(rng, (1.0, 0.0), 0.0, 0.2, 0.3, 0.05, 3000)  # no stem under it
    search = search_plants(
        colored(np.concatenate([with_stem, floating]), LEAF_RGB), NO_SOIL, PlantSettings(), 0.15
    )
    assert [p.from_stem for p in search.plants] == [True, False]
    assert search.plants[1].traits.points == 3000


def test_the_grid_prior_finds_a_faint_stem_and_reports_missing_and_extra_plants() -> None:
    rng = np.random.default_rng(5)
    a, b = crossing_pair(rng)
    faint = b[3000:]  # B's leaves; its stem mostly unseen...
    stem = cylinder(rng, 0.8, 0.0, 0.01, 0.35, 3000)
    stem = stem[(stem[:, 2] < 0.03) | (stem[:, 2] > 0.12)]  # ...but at its foot and above a leaf
    extra = plant(rng, (0.4, 0.6), [(90.0, 0.1, 0.2, 0.05)])
    points = np.concatenate([a, faint, stem, extra])
    cloud = colored(points, LEAF_RGB)
    without = search_plants(cloud, NO_SOIL, PlantSettings(), 0.15)
    # without the prior B's faint stem is not taken: A swallows B through the touching leaves
    assert not any(np.hypot(p.traits.x_m - 0.8, p.traits.y_m) < 0.05 for p in without.plants)

    nodes = grid_nodes(1, 3, 0.8, 0.8, (0.0, 0.0), 0.0, np.eye(4))
    search = search_plants(cloud, NO_SOIL, PlantSettings(), 0.15, nodes)
    cells = {p.grid_cell for p in search.plants}
    assert (1, 1) in cells and (1, 2) in cells
    assert search.missing_cells == [(1, 3)]
    assert len(search.extra_plants) == 1
    assert search.warnings(0.005)[-2:] == [
        "1 planting-grid cells without a plant: row 1 column 3",
        f"1 plants off the planting grid: {search.extra_plants[0]}",
    ]
    b_plant = next(p for p in search.plants if p.grid_cell == (1, 2))
    assert b_plant.traits.width_m == pytest.approx(width_m(b), abs=0.01)


def test_grid_cells_the_captures_did_not_see_are_not_reported_missing() -> None:
    """A mission over part of the plot: the grid's far cells are outside the captured ground."""
    rng = np.random.default_rng(8)
    points = np.concatenate([plant(rng, (0.0, 0.0), [(0.0, 0.12, 0.3, 0.1)])])
    soil = ground_patch(rng, 1.0, 4000)  # the ground seen: |x|, |y| <= 1 m
    nodes = grid_nodes(1, 4, 0.8, 0.8, (0.0, 0.0), 0.0, np.eye(4))  # x = 0, 0.8, 1.6, 2.4
    search = search_plants(colored(points, LEAF_RGB), soil, PlantSettings(), 0.15, nodes)
    assert [p.grid_cell for p in search.plants] == [(1, 1)]
    assert search.missing_cells == [(1, 2)]  # seen, empty
    assert search.unseen_cells == [(1, 3), (1, 4)]
    assert search.warnings(0.005) == [
        "1 planting-grid cells without a plant: row 1 column 2",
        "2 planting-grid cells outside what the captures saw (not searched)",
    ]


def test_points_two_stems_reach_alike_are_flagged() -> None:
    rng = np.random.default_rng(6)
    left = plant(rng, (0.0, 0.0), [(0.0, 0.1, 0.38, 0.0)])
    right = plant(rng, (0.8, 0.0), [(180.0, 0.1, 0.38, 0.0)])
    blob = rng.normal([0.4, 0.0, 0.1], 0.01, (1500, 3))  # a clump where both leaf tips meet
    search = search_plants(
        colored(np.concatenate([left, right, blob]), LEAF_RGB), NO_SOIL, PlantSettings(), 0.15
    )
    shares = [p.ambiguous_share for p in search.plants]
    assert len(shares) == 2 and all(s > 0.01 for s in shares)
    assert search.warnings(0.005)[0].startswith("plant 1: ")
    lone = search_plants(colored(left, LEAF_RGB), NO_SOIL, PlantSettings(), 0.15)
    assert lone.plants[0].ambiguous_share == 0.0


def test_grid_nodes_follow_the_map_frame_and_the_row_direction() -> None:
    T_field_map = np.eye(4)
    T_field_map[:2, 3] = [-1.6, -1.6]
    nodes = grid_nodes(2, 3, 0.75, 0.25, (0.4, 0.4), 90.0, T_field_map)
    assert nodes.row.tolist() == [1, 1, 1, 2, 2, 2] and nodes.column.tolist() == [1, 2, 3] * 2
    # along a row (+y in the map), rows to its left (-x)
    np.testing.assert_allclose(nodes.xy_m[1] - nodes.xy_m[0], [0.0, 0.25], atol=1e-12)
    np.testing.assert_allclose(nodes.xy_m[3] - nodes.xy_m[0], [-0.75, 0.0], atol=1e-12)
    np.testing.assert_allclose(nodes.xy_m[0], [-1.2, -1.2], atol=1e-12)


def test_stems_at_empty_nodes_index_the_soil_once_however_many_nodes(monkeypatch) -> None:
    """The weaker stem test at empty grid nodes asks the local ground twice per node: one
    plan-view tree over the soil serves them all (a tree per question made the plants step of a
    9 x 9 plot, 164 empty nodes over its whole soil, take 107 s of CPU instead of 9.6 s)."""
    from fieldapp.recon import grid, stems

    rng = np.random.default_rng(11)
    points = np.concatenate([plant(rng, (0.8 * i, 0.0), [(0.0, 0.12, 0.3, 0.1)]) for i in range(6)])
    soil = ground_patch(rng, 3.0, 4000)
    nodes = grid_nodes(1, 6, 0.8, 0.8, (0.0, 0.0), 0.0, np.eye(4))
    built: list[int] = []

    class CountingTree(stems.cKDTree):  # type: ignore[misc]
        def __init__(self, data, *args, **kwargs) -> None:
            built.append(len(data))
            super().__init__(data, *args, **kwargs)

    monkeypatch.setattr(stems, "cKDTree", CountingTree)
    monkeypatch.setattr(grid, "cKDTree", CountingTree)
    found = grid.stems_at_empty_nodes(points, soil, [], nodes, StemSettings())
    assert len(found) == 6  # every node asked, and each found its plant's stem
    assert built.count(len(soil)) == 1


def test_the_plants_step_indexes_the_soil_once(monkeypatch) -> None:
    """The stems' local ground (twice), the weaker test at empty nodes, each plant's soil and
    the grid's seen nodes share one plan-view tree over the soil (five were built: 0.2 s of a
    3 x 3 plot's 0.44 s, issue 22); the plants are the same."""
    from fieldapp.recon import grid, plants, stems

    rng = np.random.default_rng(8)
    points = np.concatenate([plant(rng, (0.0, 0.0), [(0.0, 0.12, 0.3, 0.1)])])
    soil = ground_patch(rng, 1.0, 4000)
    nodes = grid_nodes(1, 4, 0.8, 0.8, (0.0, 0.0), 0.0, np.eye(4))
    built: list[int] = []

    class CountingTree(stems.cKDTree):  # type: ignore[misc]
        def __init__(self, data, *args, **kwargs) -> None:
            built.append(len(data))
            super().__init__(data, *args, **kwargs)

    for module in (plants, stems, grid):
        monkeypatch.setattr(module, "cKDTree", CountingTree)
    search = search_plants(colored(points, LEAF_RGB), soil, PlantSettings(), 0.15, nodes)
    assert [p.grid_cell for p in search.plants] == [(1, 1)]
    assert search.missing_cells == [(1, 2)] and search.unseen_cells == [(1, 3), (1, 4)]
    assert built.count(len(soil)) == 1


def _row_with_a_hidden_foot(rng: np.random.Generator, third: bool) -> tuple[np.ndarray, ...]:
    """Three plants 80 cm apart along x whose long leaves reach into each other's space and
    touch; the third (at x = 1.6, the plot's edge) seen only from 12 cm up, or absent with the
    second's leaf reaching over its node 12-20 cm up."""
    leaves = [(0.0, 0.2, 0.75, 0.15), (180.0, 0.25, 0.75, 0.12)]
    a = plant(rng, (0.0, 0.0), leaves)
    b = plant(rng, (0.8, 0.0), [(0.0, 0.2, 0.85, 0.15), (180.0, 0.25, 0.75, 0.12)])
    c = plant(rng, (1.6, 0.0), leaves)
    c = c[c[:, 2] > 0.12]
    return (a, b, c) if third else (a, b)


def test_a_plant_whose_foot_is_hidden_is_found_at_its_grid_node() -> None:
    """At an empty planting-grid node the stem is looked for with its band raised: the third
    plant, seen from 12 cm up, is no longer taken whole by its neighbour along their leaves."""
    rng = np.random.default_rng(12)
    own = _row_with_a_hidden_foot(rng, third=True)
    points = colored(np.concatenate(own), LEAF_RGB)
    soil = ground_patch(rng, 1.5, 20000)
    soil[:, 0] += 0.8
    nodes = grid_nodes(1, 3, 0.8, 0.8, (0.0, 0.0), 0.0, np.eye(4))
    search = search_plants(points, soil, PlantSettings(), 0.3, nodes)
    assert len(search.plants) == 3
    assert not search.missing_cells
    third = min(search.plants, key=lambda p: abs(p.traits.x_m - 1.6))
    assert own_share(third.cloud, own[2]) > 0.9
    assert third.traits.width_m == pytest.approx(width_m(own[2]), abs=0.05)
    without_grid = search_plants(points, soil, PlantSettings(), 0.3)
    assert len(without_grid.plants) == 2  # no stem: the neighbour takes it (the old behaviour)


def test_an_empty_node_under_a_neighbours_leaf_stays_missing() -> None:
    rng = np.random.default_rng(13)
    points = colored(np.concatenate(_row_with_a_hidden_foot(rng, third=False)), LEAF_RGB)
    soil = ground_patch(rng, 1.5, 20000)
    soil[:, 0] += 0.8
    nodes = grid_nodes(1, 3, 0.8, 0.8, (0.0, 0.0), 0.0, np.eye(4))
    search = search_plants(points, soil, PlantSettings(), 0.3, nodes)
    assert len(search.plants) == 2
    assert search.missing_cells == [(1, 3)]


def test_a_stem_search_no_higher_than_its_band_still_looks_at_empty_nodes() -> None:
    """``search_height_m`` under ``band_m``: the band is not raised, and the node is still
    searched once (its stem found)."""
    rng = np.random.default_rng(14)
    points = plant(rng, (0.0, 0.0), [(0.0, 0.12, 0.3, 0.1)])
    soil = ground_patch(rng, 1.0, 4000)
    nodes = grid_nodes(1, 1, 0.8, 0.8, (0.0, 0.0), 0.0, np.eye(4))
    low = StemSettings(search_height_m=0.1)
    assert len(stems_at_empty_nodes(points, soil, [], nodes, low)) == 1
