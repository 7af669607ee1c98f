"""Plants told from soil by geometry alone, for captures without (useful) colour.

Real soil is not flat, so "above the ground plane" is not enough: the local ground is modelled
from the station's soil sample (a low percentile per 10 cm cell, so plants standing in a cell
do not lift it; empty cells take their nearest neighbour's; bilinear between cell centres),
and a point's height is taken above it. A point is a plant point when it stands at least
``LOW_M`` clear of the local ground *and* is connected (through occupied 1.5 cm voxels) to
points standing at least ``PLANT_MIN_M`` clear: a leaf drooping to the soil keeps its tip, a
soil clod or a noisy patch of soil, connected to nothing tall, is dropped; and so is the top
of a clod that a low leaf touches (:func:`clod_tops`), with whatever held on through it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from fieldapp.recon.settings import FilterSettings

GROUND_CELL_M = 0.10
GROUND_PERCENTILE = 0.2
MIN_CELL_POINTS = 4
LOW_M = 0.012
PLANT_MIN_M: float = FilterSettings.model_fields["geometry_plant_min_m"].default
"""How far above the local ground a connected group must reach to be a plant
(``FilterSettings.geometry_plant_min_m``): clods and stones stand up to 5-6 cm out of a
tilled seedbed over its local ground (a simulated plot with clods 1-4.5 cm out of a soil with
2 cm of relief: 87 groups of 3-6.4 cm became "plants" with the 3 cm of before, every seedling
then 20-35 cm). Without colour a clod and a seedling shorter than this look the same, and so
does a leaf seen cut from its base by a gap that stays below it: it is lost (an independent
renderer's flat plot: one plant 4.3 cm narrower; letting groups beside a plant in on a lower
bar brought the clods back: 11 "plants" on the cloddy plot)."""
LINK_VOXEL_M = 0.015


class LocalGround:
    """The local ground under a station's soil sample ``soil_m`` (M, 3) (which may hold some
    plant points: a low percentile per cell ignores them): the :data:`GROUND_PERCENTILE` of z
    in each ``cell_m`` cell of the field's lattice of cells holding :data:`MIN_CELL_POINTS`,
    empty cells the nearest such cell's, bilinear between cell centres, flat beyond the
    sample. Built once, read under any points (:meth:`under`): a station's raw and steady
    plant points, its soil sample itself."""

    def __init__(self, soil_m: NDArray[np.float64], cell_m: float = GROUND_CELL_M):
        self._cell_m = cell_m
        self._flat: float | None = 0.0
        self._origin = np.zeros(2)
        self._grid = np.zeros((1, 1))
        if len(soil_m) < MIN_CELL_POINTS:
            return
        # on the lattice of the field, not of whatever a call's points span: where a cell's
        # edges lie never depends on which points are asked about
        self._origin = np.floor(soil_m[:, :2].min(axis=0) / cell_m) * cell_m
        top = soil_m[:, :2].max(axis=0)
        shape = tuple(np.floor((top - self._origin) / cell_m).astype(int) + 1)
        grid = _cell_percentiles(soil_m, self._origin, cell_m, shape)
        empty = np.isnan(grid)
        if empty.all():
            self._flat = float(np.median(soil_m[:, 2]))
            return
        nearest = ndimage.distance_transform_edt(empty, return_distances=False, return_indices=True)
        self._grid = grid[tuple(nearest)]
        self._flat = None

    def under(self, xy_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N,) the local ground's height under ``xy_m`` (N, 2)."""
        if self._flat is not None:
            return np.full(len(xy_m), self._flat)
        coords = ((xy_m - self._origin) / self._cell_m - 0.5).T
        return ndimage.map_coordinates(self._grid, coords, order=1, mode="nearest")  # type: ignore[no-any-return]


def _cell_percentiles(
    soil_m: NDArray[np.float64], origin: NDArray[np.float64], cell_m: float, shape: tuple[int, ...]
) -> NDArray[np.float64]:
    """(X, Y) the low percentile of z per cell, NaN where a cell has too few points."""
    ij = np.floor((soil_m[:, :2] - origin) / cell_m).astype(np.int64)
    cell = ij[:, 0] * shape[1] + ij[:, 1]
    # sorted by cell, then by z: one sort of an integer key (cell, rank of z), the order
    # np.lexsort((z, cell)) gives at a third of its cost
    rank = np.empty(len(soil_m), dtype=np.int64)
    rank[np.argsort(soil_m[:, 2])] = np.arange(len(soil_m))
    order = np.argsort(cell * len(soil_m) + rank)
    cells_sorted = cell[order]
    start = np.flatnonzero(np.diff(cells_sorted, prepend=-1))
    count = np.diff(start, append=len(order))
    grid = np.full(shape[0] * shape[1], np.nan)
    enough = count >= MIN_CELL_POINTS
    pick = start[enough] + np.floor(GROUND_PERCENTILE * (count[enough] - 1)).astype(np.int64)
    grid[cells_sorted[start[enough]]] = soil_m[order[pick], 2]
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


def station_ground(soil_m: NDArray[np.float64], soil_band_m: float) -> LocalGround:
    """The local ground of the soil sample's points ``soil_m`` (M, 3) within ``soil_band_m``
    of the station's plane (z = 0)."""
    return LocalGround(soil_m[np.abs(soil_m[:, 2]) <= soil_band_m])


def height_above(ground: LocalGround, points_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) the height of each of ``points_m`` (N, 3) above ``ground``."""
    return points_m[:, 2] - ground.under(points_m[:, :2])


def plants_above_local_ground(
    points_m: NDArray[np.float64],
    soil_m: NDArray[np.float64],
    soil_band_m: float,
    own_m: NDArray[np.float64] | None = None,
    plant_min_m: float = PLANT_MIN_M,
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """Plant points of a levelled station (z up, z = 0 the station's ground plane).

    ``points_m``: (N, 3) every measured point; ``soil_m``: (M, 3) the sparse soil sample (all
    pixels of a sparse grid). ``own_m``: (N, 3) the same points at their own depths where
    ``points_m`` are their blocks' medians: a point must stand clear at both, or a soil pixel
    beside a low leaf, whose block's median the leaf lifts, joins the plant at the soil's
    own depth. ``plant_min_m``: how far above the local ground a plant must reach
    (:data:`PLANT_MIN_M`). Returns (is_plant (N,), the height of each point (N,) and of each
    soil-sample point (M,) above the local ground).
    """
    ground = station_ground(soil_m, soil_band_m)
    height, soil_height = height_above(ground, points_m), height_above(ground, soil_m)
    low = height > LOW_M
    if own_m is not None:
        low &= height_above(ground, own_m) > LOW_M
    is_plant = np.zeros(len(points_m), dtype=bool)
    candidates = np.flatnonzero(low)
    if len(candidates):
        is_plant[candidates] = connected_to_tall(
            points_m[candidates], height[candidates] > plant_min_m
        )
        clods = clod_tops(points_m, height, is_plant)
        if clods.any():  # what held on to the plant only through a clod goes with it
            kept = np.flatnonzero(is_plant & ~clods)
            is_plant[:] = False
            is_plant[kept] = connected_to_tall(points_m[kept], height[kept] > plant_min_m)
    return is_plant, height, soil_height


CLOD_TOP_M = 0.045
"""Clods and stones of a tilled seedbed stand at most this far out of the local ground."""
CLOD_CELL_M = 0.01
CLOD_RADIUS_CELLS = 2
"""A clod's top is at least a disc of this radius in cells across (5 cm): wider than a
seedling's leaf blade lying low (1.5-4 cm)."""
CLOD_CLEAR_M = 0.02
"""Plant points this far above :data:`CLOD_TOP_M` in a cell: something grows over it (a stem,
a leaf), and the low points under it are no clod's."""


def clod_tops(
    points_m: NDArray[np.float64], height_m: NDArray[np.float64], is_plant: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """(N,) which of the plant points (``is_plant`` (N,) of ``points_m`` (N, 3), ``height_m``
    (N,) above the local ground) are the top of a clod that a low leaf touches, and joined the
    plant through it: the points under :data:`CLOD_TOP_M` whose cells (plan view,
    :data:`CLOD_CELL_M`) have nothing of the plant above them and fill, small holes closed, a
    disc :data:`CLOD_RADIUS_CELLS` in radius (a morphological opening of those cells). A leaf
    blade lying low is narrower than the disc and a stem has itself above its foot; a lump
    that wide and that low with nothing over it is soil. Without colour, the sixth
    independent renderer's seedling plots measured their widths 4.71 and 4.25 cm RMSE, plants
    up to 13.5 cm too wide by the clods their low leaves touch; with this 1.66 and 1.74 cm
    (RECONSTRUCTION.md, "Clods under low leaves"). The price: a leaf wider than the disc lying
    within :data:`CLOD_TOP_M` of the soil with nothing above it is taken for a clod."""
    clods = np.zeros(len(points_m), dtype=bool)
    plant = np.flatnonzero(is_plant)
    height = height_m[plant]
    low = height < CLOD_TOP_M
    if not low.any():
        return clods
    xy = points_m[plant, :2]
    cells = np.floor((xy - xy.min(axis=0)) / CLOD_CELL_M).astype(np.int64)
    shape = tuple(cells.max(axis=0) + 1)
    occupied = np.zeros(shape, dtype=bool)
    occupied[tuple(cells[low].T)] = True
    over = np.zeros(shape, dtype=bool)
    over[tuple(cells[height >= CLOD_TOP_M + CLOD_CLEAR_M].T)] = True
    square = np.ones((3, 3), dtype=bool)
    free = ndimage.binary_closing(occupied & ~over, structure=square) & ~over
    r = CLOD_RADIUS_CELLS
    across, along = np.mgrid[-r : r + 1, -r : r + 1]
    tops = ndimage.binary_opening(free, structure=across**2 + along**2 <= r * r)
    clods[plant[low]] = tops[tuple(cells[low].T)]
    return clods
