"""Stem feet: where plants stand, found from the part of a plant that never touches a neighbour.

Leaves of neighbouring plants reach across the rows and touch; the stem's foot does not. In the
lowest ``band_m`` above the *local* ground a stem is a tall, narrow stack of points; a leaf tip
resting on the soil or hanging into the band is flat or slanted and fills a few heights only.
So the plant cloud's low points are binned into ``cell_m`` columns, each column's occupied
``cell_m`` height layers are counted over its 3 x 3 neighbourhood, and columns filling at least
``min_layer_fraction`` of the band's layers, starting within ``max_foot_gap_m`` of the ground,
are stem columns; adjacent stem columns form one stem, and stems closer than
``min_separation_m`` are one plant (listed as a merge).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

from fieldapp.recon.settings import StemSettings

GROUND_NEIGHBOURS = 8
"""Soil points whose median height is the local ground under a point."""
GROUND_CELL_M = 0.02
"""Points in one cell of this size (plan view) share their local ground."""


@dataclass(frozen=True)
class Stem:
    """A stem foot: ``xy_m`` (2,) in the field frame, the local ground ``ground_z_m`` there and
    the share of the band's height layers its column fills (1.0: seen from the soil up)."""

    xy_m: NDArray[np.float64]
    ground_z_m: float
    layer_fraction: float


def local_ground_z_m(
    soil_m: NDArray[np.float64],
    xy_m: NDArray[np.float64],
    fallback_z_m: float = 0.0,
    soil_tree: cKDTree | None = None,
) -> NDArray[np.float64]:
    """(N,) the median z of the :data:`GROUND_NEIGHBOURS` soil points (M, 3) nearest each
    ``xy_m`` (N, 2) in plan view (taken at the centre of its :data:`GROUND_CELL_M` cell);
    ``fallback_z_m`` everywhere when there is no soil. ``soil_tree``: the plan-view tree over
    ``soil_m[:, :2]`` when the caller asks many times (built here otherwise)."""
    if len(soil_m) == 0 or len(xy_m) == 0:
        return np.full(len(xy_m), fallback_z_m)
    cells = np.floor(xy_m / GROUND_CELL_M).astype(np.int64)
    packed = (cells[:, 0] + (1 << 30)) << 32 | (cells[:, 1] + (1 << 30))
    _, first, inverse = np.unique(packed, return_index=True, return_inverse=True)
    centres = (cells[first] + 0.5) * GROUND_CELL_M
    k = min(GROUND_NEIGHBOURS, len(soil_m))
    tree = cKDTree(soil_m[:, :2]) if soil_tree is None else soil_tree
    _, index = tree.query(centres, k=k)
    index = np.asarray(index).reshape(len(centres), k)
    return np.median(soil_m[index, 2], axis=1)[inverse.ravel()]  # type: ignore[no-any-return]


def stem_columns(
    points_m: NDArray[np.float64], heights_m: NDArray[np.float64], settings: StemSettings
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.float64]]:
    """The columns of the band: (origin (2,), cells (C, 2) of stem columns, their layer
    fractions (C,)). ``points_m`` (N, 3) and their ``heights_m`` (N,) above the local ground."""
    layers = max(round(settings.band_m / settings.cell_m), 1)
    in_band = (heights_m >= 0.0) & (heights_m < layers * settings.cell_m)
    band, h = points_m[in_band], heights_m[in_band]
    if len(band) == 0:
        return np.zeros(2), np.zeros((0, 2), np.intp), np.zeros(0)
    origin = band[:, :2].min(axis=0) - 2 * settings.cell_m
    cells = np.floor((band[:, :2] - origin) / settings.cell_m).astype(np.intp)
    layer = np.minimum((h / settings.cell_m).astype(np.intp), layers - 1)
    shape = (*(cells.max(axis=0) + 3), layers)
    occupied = np.zeros(shape, dtype=bool)
    occupied[cells[:, 0], cells[:, 1], layer] = True
    # a layer counts when any column of the 3 x 3 neighbourhood has points at that height
    spread = ndimage.maximum_filter(occupied, size=(3, 3, 1), mode="constant")
    filled = spread.sum(axis=2) / layers
    lowest = np.where(spread.any(axis=2), np.argmax(spread, axis=2), layers)
    near_ground = lowest * settings.cell_m <= settings.max_foot_gap_m
    stem = (filled >= settings.min_layer_fraction) & near_ground & occupied.any(axis=2)
    found = np.argwhere(stem)
    return origin, found.astype(np.intp), filled[stem].astype(np.float64)


def find_stems(
    points_m: NDArray[np.float64],
    soil_m: NDArray[np.float64],
    settings: StemSettings,
    soil_tree: cKDTree | None = None,
) -> tuple[list[Stem], int]:
    """Stem feet in the plant cloud (N, 3, field frame) over the soil sample (M, 3), and how
    many stem candidates were merged into a nearer, stronger one. ``soil_tree``: the plan-view
    tree over ``soil_m[:, :2]`` when the caller has one (see :func:`local_ground_z_m`)."""
    low = points_m[:, 2] <= points_m[:, 2].min(initial=0.0) + settings.search_height_m
    candidates = points_m[low]
    if len(candidates) == 0:
        return [], 0
    if soil_tree is None and len(soil_m):  # one tree for both questions: 0.04 s each
        soil_tree = cKDTree(soil_m[:, :2])
    ground = local_ground_z_m(soil_m, candidates[:, :2], soil_tree=soil_tree)
    origin, cells, fractions = stem_columns(candidates, candidates[:, 2] - ground, settings)
    if len(cells) == 0:
        return [], 0
    grid = np.zeros(tuple(cells.max(axis=0) + 1), dtype=np.float64)
    grid[cells[:, 0], cells[:, 1]] = fractions
    labels, count = ndimage.label(grid > 0, structure=np.ones((3, 3)))
    index = np.arange(1, count + 1)
    centres = np.array(ndimage.center_of_mass(grid, labels, index)).reshape(-1, 2)
    strengths = np.asarray(ndimage.maximum(grid, labels, index), dtype=np.float64).reshape(-1)
    stems = [
        (float(strength), origin + (centre + 0.5) * settings.cell_m)
        for strength, centre in zip(strengths, centres, strict=True)
    ]
    return _merge_close(stems, soil_m, settings.min_separation_m, soil_tree)


def merged_into(
    xy_m: NDArray[np.float64], strength: NDArray[np.float64], min_separation_m: float
) -> NDArray[np.intp]:
    """(N,) for each of the places ``xy_m`` (N, 2), the one it is merged into (itself when
    kept): strongest first (the earlier of equals), each kept unless it stands within
    ``min_separation_m`` of one kept before it, then merged into the first such. Two stems,
    or two plants' bases, are never that close."""
    into = np.arange(len(xy_m))
    kept: list[int] = []
    for i in sorted(range(len(xy_m)), key=lambda i: -strength[i]):
        near = [k for k in kept if np.linalg.norm(xy_m[i] - xy_m[k]) < min_separation_m]
        if near:
            into[i] = near[0]
        else:
            kept.append(i)
    return into


def _merge_close(
    stems: list[tuple[float, NDArray[np.float64]]],
    soil_m: NDArray[np.float64],
    min_separation_m: float,
    soil_tree: cKDTree | None,
) -> tuple[list[Stem], int]:
    """Strongest first; a stem within ``min_separation_m`` of a kept one is merged into it."""
    into = merged_into(
        np.array([xy for _, xy in stems]).reshape(-1, 2),
        np.array([strength for strength, _ in stems]),
        min_separation_m,
    )
    order = sorted(np.flatnonzero(into == np.arange(len(stems))), key=lambda i: -stems[i][0])
    kept = [stems[i] for i in order]
    xy_all = np.array([xy for _, xy in kept]).reshape(-1, 2)
    ground = local_ground_z_m(soil_m, xy_all, soil_tree=soil_tree)
    result = [Stem(xy, float(z), strength) for (strength, xy), z in zip(kept, ground, strict=True)]
    return result, len(stems) - len(kept)
