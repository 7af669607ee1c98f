"""Leaves crossing in an X: the bend cost judged against the sheet a path is on, not against
the voxels' normals blurred from both sheets where they cross."""

from __future__ import annotations

import numpy as np
import pytest

from fieldapp.recon.geodesic import crossing_sheets, surface_normals, voxel_graph
from fieldapp.recon.plants import search_plants
from fieldapp.recon.settings import PlantSettings, StemSettings

from .synthetic import LEAF_RGB, colored
from .test_plants_stems import NO_SOIL, own_share, width_m
from .touching import x_pair


def _search(sheet_aware: bool, seed: int, follow_leaves: bool = True):  # type: ignore[no-untyped-def]
    a, b = x_pair(np.random.default_rng(seed))
    stems = StemSettings(sheet_aware=sheet_aware, follow_leaves=follow_leaves)
    settings = PlantSettings(stems=stems)
    search = search_plants(colored(np.concatenate([a, b]), LEAF_RGB), NO_SOIL, settings, 0.15)
    first, second = sorted(search.plants, key=lambda p: p.traits.x_m)
    return a, b, first, second


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_leaf_crossing_the_neighbours_in_an_x_stays_with_its_plant(seed: int) -> None:
    a, b, first, second = _search(True, seed)
    assert second.traits.width_m == pytest.approx(width_m(b), abs=0.01)
    assert first.traits.width_m == pytest.approx(width_m(a), abs=0.01)
    assert own_share(first.cloud, a) > 0.95 and own_share(second.cloud, b) > 0.95


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_with_blurred_normals_the_neighbour_takes_the_leaf_at_the_x(seed: int) -> None:
    """The reason for the sheets: with one normal per voxel, blurred from both sheets at the
    crossing, A's path pays as much going straight through the X as turning there, and B,
    whose path reaches the X along 10 cm of its own leaf, takes A's leaf around it (the
    assignment alone: the ribbons, taking a leaf's edges and the points their steps missed,
    now take it back, below)."""
    _, b, _, second = _search(False, seed, follow_leaves=False)
    assert second.traits.width_m > width_m(b) + 0.02


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_without_the_sheets_the_ribbons_take_the_leaf_at_the_x_back(seed: int) -> None:
    """Two ways to the same answer: B's assignment holds A's leaf around the X, and A's
    ribbon, run on through it, takes it back whole (before its steps took the edges and the
    points they missed, B kept enough of it to come out 6-10 cm too wide)."""
    a, b, first, second = _search(False, seed)
    assert second.traits.width_m == pytest.approx(width_m(b), abs=0.01)
    assert first.traits.width_m == pytest.approx(width_m(a), abs=0.01)


def test_where_the_leaves_cross_a_blurred_voxel_gets_its_sheet_back() -> None:
    a, b = x_pair(np.random.default_rng(0))
    graph = voxel_graph(np.concatenate([a, b]), 0.01)
    sheets = crossing_sheets(graph)
    centres = graph.centres_m
    at_x = (  # on A's level leaf, within 2 cm of where B's leaf crosses it
        (np.abs(centres[:, 0] - 0.55) < 0.03)
        & (np.abs(centres[:, 1]) < 0.02)
        & (np.abs(centres[:, 2] - 0.30) < 0.005)
    )
    blurred = np.flatnonzero(at_x & (np.abs(surface_normals(graph)[:, 2]) < np.cos(np.radians(15))))
    assert len(blurred) >= 5  # the ring normals there are pulled off A's by B's sheet
    level = sheets.voxel[np.abs(sheets.normal[:, 2]) > np.cos(np.radians(10))]
    assert np.isin(blurred, level).mean() > 0.9  # A's own sheet is a state of each


def test_the_sheets_are_the_same_whatever_the_binning_block(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The thin voxels' normals are binned to directions a block at a time (a plot-wide (V,
    200) array was 1.2 GB on a 6 x 6 touching plot): blocks of any size give the same sheets."""
    from fieldapp.recon import geodesic

    a, b = x_pair(np.random.default_rng(1))
    graph = voxel_graph(np.concatenate([a, b]), 0.01)
    whole = crossing_sheets(graph)
    monkeypatch.setattr(geodesic, "BIN_BLOCK", 7)
    blocked = crossing_sheets(graph)
    assert len(whole.voxel) >= 5
    np.testing.assert_array_equal(blocked.voxel, whole.voxel)
    np.testing.assert_array_equal(blocked.normal, whole.normal)


def test_the_sheet_graph_is_the_same_whatever_the_edge_block(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The (voxel, sheet) states' edges are costed a block of edges at a time: blocks of any
    size (here splitting the crossings' state pairs across blocks) give the same graph."""
    from fieldapp.recon import geodesic

    a, b = x_pair(np.random.default_rng(2))
    graph = voxel_graph(np.concatenate([a, b]), 0.01)
    sheets = crossing_sheets(graph)
    assert len(sheets.voxel) >= 5
    whole, voxels, bend = geodesic.sheet_graph(graph, 1.0, sheets, keep_bend=True)
    monkeypatch.setattr(geodesic, "EDGE_BLOCK", 5)
    blocked, blocked_voxels, blocked_bend = geodesic.sheet_graph(graph, 1.0, sheets, keep_bend=True)
    np.testing.assert_array_equal(blocked_voxels, voxels)
    for x, y in ((blocked, whole), (blocked_bend, bend)):
        assert (x != y).nnz == 0 and np.array_equal(x.indptr, y.indptr)
