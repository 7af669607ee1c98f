"""Plants: density clustering of the plant cloud, an optional planting-grid prior, stable ids.

Clustering is by connected components of occupied voxels (26-neighbourhood): two points are in
one plant when a chain of occupied voxels joins them. It matches DBSCAN with eps of about one
voxel and min_samples 1 and is an order of magnitude faster (PERFORMANCE-NOTES.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.filters import voxel_keys
from fieldapp.recon.settings import GridPrior, PlantSettings
from fieldapp.recon.traits import PlantTraits, measure_plant

NOISE = -1

_HALF_NEIGHBOURHOOD = [
    offset
    for offset in itertools.product((-1, 0, 1), repeat=3)
    if offset > (0, 0, 0)  # 13 of the 26 neighbours: each pair is visited once
]


def _pack(cells: NDArray[np.int64]) -> NDArray[np.int64]:
    shifted = cells + (1 << 20)
    return (shifted[:, 0] << 42) | (shifted[:, 1] << 21) | shifted[:, 2]


def voxel_components(points_m: NDArray[np.float64], voxel_m: float) -> NDArray[np.intp]:
    """(N,) component label of every point (0-based) among 26-connected occupied voxels."""
    if len(points_m) == 0:
        return np.zeros(0, dtype=np.intp)
    voxel_keys(points_m, voxel_m)  # validates the extent
    cells = np.floor(points_m / voxel_m).astype(np.int64)
    unique_cells, inverse = np.unique(cells, axis=0, return_inverse=True)
    unique = _pack(unique_cells)  # sorted, as np.unique sorts cells lexicographically
    rows, cols = [], []
    for offset in _HALF_NEIGHBOURHOOD:
        neighbour_keys = _pack(unique_cells + np.array(offset, dtype=np.int64))
        at = np.clip(np.searchsorted(unique, neighbour_keys), 0, len(unique) - 1)
        found = unique[at] == neighbour_keys
        rows.append(np.flatnonzero(found))
        cols.append(at[found])
    row, col = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(row)), (row, col)), shape=(len(unique), len(unique)))
    _, component = connected_components(graph, directed=False)
    return component[inverse.ravel()].astype(np.intp)  # type: ignore[no-any-return]


def drop_small(labels: NDArray[np.intp], min_points: int) -> NDArray[np.intp]:
    """Labels with clusters of fewer than ``min_points`` points set to :data:`NOISE`."""
    out = labels.copy()
    valid = labels >= 0
    counts = np.bincount(labels[valid]) if valid.any() else np.zeros(0, dtype=np.intp)
    small = valid & (counts[np.where(valid, labels, 0)] < min_points)
    out[small] = NOISE
    return out


def grid_nodes_m(grid: GridPrior) -> NDArray[np.float64]:
    """(rows * columns, 2) xy of the planting grid's nodes, row by row."""
    j, i = np.mgrid[0 : grid.rows, 0 : grid.columns]
    x = grid.origin_x_m + i.ravel() * grid.column_spacing_m
    y = grid.origin_y_m + j.ravel() * grid.row_spacing_m
    return np.stack([x, y], axis=1).astype(np.float64)


def apply_grid_prior(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    grid: GridPrior,
    base_height_m: float,
) -> NDArray[np.intp]:
    """Split clusters whose stems stand at several grid nodes and merge clusters whose stems
    stand at one node.

    A cluster claims a node when some of its points lower than ``base_height_m`` above the
    ground lie within ``grid.snap_radius_m`` of the node. A cluster claiming several nodes is
    split by the nearest node; clusters claiming the same single node become one plant.
    Clusters claiming no node are left alone.
    """
    nodes = grid_nodes_m(grid)
    distance = np.linalg.norm(points_m[:, None, :2] - nodes[None], axis=2)
    nearest = np.argmin(distance, axis=1)
    near = distance[np.arange(len(points_m)), nearest] <= grid.snap_radius_m
    low = points_m[:, 2] <= base_height_m
    out = labels.copy()
    next_label = int(labels.max(initial=-1)) + 1
    node_label: dict[int, int] = {}
    for label in np.unique(labels[labels >= 0]):
        members = labels == label
        claimed = np.unique(nearest[members & near & low])
        if len(claimed) == 0:
            continue
        targets = np.array(
            [node_label.setdefault(int(node), next_label + int(node)) for node in claimed]
        )
        closest = np.argmin(distance[members][:, claimed], axis=1)
        out[members] = targets[closest]
    return out


def order_by_position(positions_m: NDArray[np.float64], row_gap_m: float) -> list[int]:
    """Indices of plants at ``positions_m`` (N, 2) in reading order: rows by y (a new row when
    the gap in y exceeds ``row_gap_m``), then x within a row. Ids numbered in this order stay
    the same when the plot is scanned again."""
    by_y = sorted(range(len(positions_m)), key=lambda i: float(positions_m[i, 1]))
    rows: list[list[int]] = []
    for index in by_y:
        if rows and positions_m[index, 1] - positions_m[rows[-1][-1], 1] <= row_gap_m:
            rows[-1].append(index)
        else:
            rows.append([index])
    return [i for row in rows for i in sorted(row, key=lambda i: float(positions_m[i, 0]))]


@dataclass(frozen=True)
class Plant:
    """One plant: its id (1-based, in reading order), its traits and its points."""

    id: int
    traits: PlantTraits
    cloud: Cloud


def find_plants(
    cloud: Cloud, soil_m: NDArray[np.float64], settings: PlantSettings, ground_radius_m: float
) -> list[Plant]:
    """Split the plot's plant cloud (field frame) into plants and measure each one."""
    labels = drop_small(
        voxel_components(cloud.points, settings.cluster_voxel_m), settings.min_points
    )
    if settings.grid is not None:
        labels = apply_grid_prior(cloud.points, labels, settings.grid, 2 * settings.base_slice_m)
    measured: list[tuple[PlantTraits, Cloud]] = []
    for label in np.unique(labels[labels >= 0]):
        plant = cloud.select(labels == label)
        traits = measure_plant(
            plant.points,
            soil_m,
            settings.base_slice_m,
            ground_radius_m,
            settings.top_support_points,
            settings.top_support_radius_m,
        )
        if traits.height_m >= settings.min_height_m and len(plant) >= settings.min_points:
            measured.append((traits, plant))
    positions = np.array([[t.x_m, t.y_m] for t, _ in measured]).reshape(-1, 2)
    order = order_by_position(positions, settings.row_gap_m)
    return [Plant(i + 1, *measured[index]) for i, index in enumerate(order)]
