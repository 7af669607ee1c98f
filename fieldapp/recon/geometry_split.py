"""Plants told from soil by geometry alone, for captures without (useful) colour.

Real soil is not flat, so "above the ground plane" is not enough: the local ground is modelled
from the station's soil sample (a low percentile per 10 cm cell, so plants standing in a cell
do not lift it; empty cells take their nearest neighbour's; bilinear between cell centres),
and a point's height is taken above it. A point is a plant point when it stands at least
``LOW_M`` clear of the local ground *and* is connected (through occupied 1.5 cm voxels) to
points standing at least ``HIGH_M`` clear: a leaf drooping to the soil keeps its tip, a soil
clod or a noisy patch of soil, connected to nothing tall, is dropped.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

GROUND_CELL_M = 0.10
GROUND_PERCENTILE = 0.2
MIN_CELL_POINTS = 4
LOW_M = 0.012
HIGH_M = 0.03
LINK_VOXEL_M = 0.015


def local_ground_m(
    soil_m: NDArray[np.float64], xy_m: NDArray[np.float64], cell_m: float = GROUND_CELL_M
) -> NDArray[np.float64]:
    """(N,) the local ground's height under ``xy_m`` (N, 2), from the soil sample ``soil_m``
    (M, 3) (which may hold some plant points: a low percentile per cell ignores them)."""
    if len(soil_m) < MIN_CELL_POINTS:
        return np.zeros(len(xy_m))
    origin = np.minimum(soil_m[:, :2].min(axis=0), xy_m.min(axis=0, initial=np.inf))
    top = np.maximum(soil_m[:, :2].max(axis=0), xy_m.max(axis=0, initial=-np.inf))
    shape = tuple(np.floor((top - origin) / cell_m).astype(int) + 1)
    grid = _cell_percentiles(soil_m, origin, cell_m, shape)
    empty = np.isnan(grid)
    if empty.all():
        return np.full(len(xy_m), float(np.median(soil_m[:, 2])))
    nearest = ndimage.distance_transform_edt(empty, return_distances=False, return_indices=True)
    grid = grid[tuple(nearest)]
    coords = ((xy_m - origin) / cell_m - 0.5).T
    return ndimage.map_coordinates(grid, coords, order=1, mode="nearest")  # type: ignore[no-any-return]


def _cell_percentiles(
    soil_m: NDArray[np.float64], origin: NDArray[np.float64], cell_m: float, shape: tuple[int, ...]
) -> NDArray[np.float64]:
    """(X, Y) the low percentile of z per cell, NaN where a cell has too few points."""
    ij = np.floor((soil_m[:, :2] - origin) / cell_m).astype(np.int64)
    cell = ij[:, 0] * shape[1] + ij[:, 1]
    order = np.lexsort((soil_m[:, 2], cell))
    cells, start, count = np.unique(cell[order], return_index=True, return_counts=True)
    grid = np.full(shape[0] * shape[1], np.nan)
    enough = count >= MIN_CELL_POINTS
    pick = start[enough] + np.floor(GROUND_PERCENTILE * (count[enough] - 1)).astype(np.int64)
    grid[cells[enough]] = soil_m[order[pick], 2]
    return grid.reshape(shape)


def connected_to_tall(
    points_m: NDArray[np.float64], tall: NDArray[np.bool_], voxel_m: float = LINK_VOXEL_M
) -> NDArray[np.bool_]:
    """(N,) which of ``points_m`` (N, 3) lie in a connected group of occupied voxels (26
    neighbours) that holds at least one ``tall`` point."""
    if not tall.any():
        return np.zeros(len(points_m), dtype=bool)
    cells = np.floor((points_m - points_m.min(axis=0)) / voxel_m).astype(np.int64)
    occupied = np.zeros(tuple(cells.max(axis=0) + 1), dtype=bool)
    occupied[tuple(cells.T)] = True
    labels, _ = ndimage.label(occupied, structure=np.ones((3, 3, 3), dtype=bool))
    point_label = labels[tuple(cells.T)]
    return np.isin(point_label, np.unique(point_label[tall]))


def height_above_local_ground(
    points_m: NDArray[np.float64], soil_m: NDArray[np.float64], soil_band_m: float
) -> NDArray[np.float64]:
    """(N,) the height of each of ``points_m`` (N, 3) above the local ground
    (:func:`local_ground_m`) of the soil sample's points within ``soil_band_m`` of the
    station's plane (z = 0)."""
    near = soil_m[np.abs(soil_m[:, 2]) <= soil_band_m]
    return points_m[:, 2] - local_ground_m(near, points_m[:, :2])


def plants_above_local_ground(
    points_m: NDArray[np.float64], soil_m: NDArray[np.float64], soil_band_m: float
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """Plant points of a levelled station (z up, z = 0 the station's ground plane).

    ``points_m``: (N, 3) every measured point; ``soil_m``: (M, 3) the sparse soil sample (all
    pixels of a sparse grid). Returns (is_plant (N,), the height of each soil-sample point
    above the local ground (M,)).
    """
    height = height_above_local_ground(points_m, soil_m, soil_band_m)
    soil_height = height_above_local_ground(soil_m, soil_m, soil_band_m)
    low = height > LOW_M
    is_plant = np.zeros(len(points_m), dtype=bool)
    candidates = np.flatnonzero(low)
    if len(candidates):
        is_plant[candidates] = connected_to_tall(points_m[candidates], height[candidates] > HIGH_M)
    return is_plant, height, soil_height
