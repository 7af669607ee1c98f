"""The bend cost of the plant graph: a leaf is followed as one smooth sheet, a path that passes
onto another surface at a contact pays."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.sparse.csgraph import dijkstra

from fieldapp.recon.geodesic import VoxelGraph, bend_weighted, surface_normals, voxel_graph

from .touching import leaf


def _nearest(graph: VoxelGraph, point_m: NDArray[np.float64] | list[float]) -> int:
    return int(np.argmin(np.linalg.norm(graph.centres_m - np.asarray(point_m), axis=1)))


def _crossing_sheets(rng: np.random.Generator) -> NDArray[np.float64]:
    """A flat 6 cm ribbon at z = 0.3 m along x (0 to 0.6 m) and an upright one across it at
    x = 0.3 m (z 0.1 to 0.5 m): two leaves touching at a right angle, seen side on."""
    flat = np.column_stack(
        [rng.uniform(0.0, 0.6, 6000), rng.uniform(-0.03, 0.03, 6000), np.full(6000, 0.3)]
    )
    upright = np.column_stack(
        [np.full(4000, 0.3), rng.uniform(-0.03, 0.03, 4000), rng.uniform(0.1, 0.5, 4000)]
    )
    points = np.concatenate([flat, upright])
    return points + rng.normal(0.0, 0.001, points.shape)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_smooth_arching_leaf_costs_next_to_nothing_more_than_its_length(seed: int) -> None:
    rng = np.random.default_rng(seed)
    arch = leaf(rng, (0.0, 0.0), 0.0, 0.2, 0.7, 0.2, 8000)  # rises 20 cm, droops, tapers
    graph = voxel_graph(arch, 0.01)
    start, tip = _nearest(graph, [0.0, 0.0, 0.2]), _nearest(graph, arch[np.argmax(arch[:, 0])])
    length = dijkstra(graph.edges, indices=start)[tip]
    bent = dijkstra(bend_weighted(graph, 1.0).edges, indices=start)[tip]
    assert length < bent <= 1.05 * length


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_path_onto_a_leaf_touching_at_an_angle_pays_for_the_bend(seed: int) -> None:
    graph = voxel_graph(_crossing_sheets(np.random.default_rng(seed)), 0.01)
    start, top = _nearest(graph, [0.0, 0.0, 0.3]), _nearest(graph, [0.3, 0.0, 0.5])
    length = dijkstra(graph.edges, indices=start)[top]
    bent = dijkstra(bend_weighted(graph, 1.0).edges, indices=start)[top]
    assert length == pytest.approx(0.5, abs=0.02)
    assert bent >= length + 0.3  # 1 - cos 90 deg = the whole 1 m at the sharpest edge, spread


def test_surface_normals_are_the_sheets_normals() -> None:
    graph = voxel_graph(_crossing_sheets(np.random.default_rng(0)), 0.01)
    normals = surface_normals(graph)
    on_flat = np.abs(graph.centres_m[:, 0] - 0.3) > 0.05
    on_upright = (np.abs(graph.centres_m[:, 2] - 0.3) > 0.05) & ~on_flat
    assert np.mean(np.abs(normals[on_flat, 2]) > 0.99) > 0.95  # the sheets' ragged edges tilt
    assert np.mean(np.abs(normals[on_upright, 0]) > 0.99) > 0.95
