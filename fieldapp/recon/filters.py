"""Plant filtering: pass-through above the ground, excess green, outlier removal, voxel means.

Cheap per-point tests (pass-through, ExG) run first, on every frame, so the neighbourhood
searches (SOR, ROR) only see the few plant points left.
"""

from __future__ import annotations

import ctypes
import logging
import os
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.exg import NOT_GREEN_EXG, excess_green, has_colour
from fieldapp.recon.geometry_split import LOW_M as LOCAL_SOIL_M
from fieldapp.recon.geometry_split import (
    LocalGround,
    height_above,
    plants_above_local_ground,
    station_ground,
)
from fieldapp.recon.settings import FilterSettings

log = logging.getLogger(__name__)

OUTLIER_QUERY_BLOCK = 16_384
"""Points per neighbour query of the outlier filters: bounds its memory, and keeps each
block's arrays (5 MB) small: with 65 536 the first query's fresh 20-40 MB arrays, which numpy
asks the kernel to back with huge pages, cost 0.3-0.4 s of system time in page faults
(compaction), as much as the rest of the stage."""
ROR_SPARE = 3
"""The radius filter keeps this many of each point's neighbours within its radius beyond the
count it asks for (:func:`outlier_masks`)."""


def pass_through(height_m: NDArray[np.float64], min_m: float, max_m: float) -> NDArray[np.bool_]:
    """Mask of the points whose height above the ground (N,) is within [min_m, max_m]."""
    return (height_m >= min_m) & (height_m <= max_m)


def statistical_outliers(
    points: NDArray[np.float64],
    neighbors: int,
    std_ratio: float,
    workers: int = 1,
    min_distance_m: float = 0.0,
) -> NDArray[np.bool_]:
    """Mask of the inliers of statistical outlier removal: a point is kept when its mean
    distance to its ``neighbors`` nearest neighbours is within ``std_ratio`` standard
    deviations of the cloud's average, or within ``min_distance_m`` (:func:`sor_limit`)."""
    if len(points) <= neighbors:
        return np.ones(len(points), dtype=bool)
    distances, _ = cKDTree(points).query(points, k=neighbors + 1, workers=workers)
    mean_distance = distances[:, 1:].mean(axis=1)
    return mean_distance <= sor_limit(mean_distance, std_ratio, min_distance_m)  # type: ignore[no-any-return]


def sor_limit(mean_distance: NDArray[np.float64], std_ratio: float, min_distance_m: float) -> float:
    """The statistical filter's limit on a point's mean distance to its neighbours: the
    cloud's average plus ``std_ratio`` standard deviations (the paper's), never under
    ``min_distance_m`` (``FilterSettings.sor_min_distance_m``).

    The paper's limit follows the spread of the cloud's own distances, so it is tight where
    there are few outliers to widen it: on an independent renderer's plot with exact depth it
    fell to 9 mm and took 2 519 points lying on the plants (the sparse tips: widths 2.4 cm
    short) against 234 more than 3 cm off them; with the floor at 20 mm, 6 against 70. Points
    on the plants' surfaces have mean distances to their 35 nearest of 6-7 mm (median) and 15-19
    mm (99.9th percentile), outliers 3 cm or more off them 14-47 mm (median); the limit measured
    on noisy plots is 26-38 mm, which the floor leaves alone."""
    limit = float(mean_distance.mean() + std_ratio * mean_distance.std())
    return max(limit, min_distance_m)


def radius_outliers(
    points: NDArray[np.float64], radius_m: float, min_points: int, workers: int = 1
) -> NDArray[np.bool_]:
    """Mask of the inliers of radius outlier removal: at least ``min_points`` other points
    within ``radius_m``."""
    if len(points) == 0:
        return np.ones(0, dtype=bool)
    tree = cKDTree(points)
    counts = tree.query_ball_point(points, radius_m, workers=workers, return_length=True)
    return counts - 1 >= min_points  # type: ignore[no-any-return]


def voxel_keys(points: NDArray[np.float64], voxel_m: float) -> NDArray[np.int64]:
    """(N,) int64: one key per voxel of edge ``voxel_m`` (21 bits per axis). An axis at a
    time: whole, the (N, 3) float and integer cells of a big plot's fused cloud (6 M points)
    were 0.4 GB of temporaries."""
    keys = np.zeros(len(points), dtype=np.int64)
    for axis, shift in ((0, 42), (1, 21), (2, 0)):
        cells = np.floor(points[:, axis] / voxel_m).astype(np.int64) + (1 << 20)
        if len(cells) and (cells.min() < 0 or cells.max() >= (1 << 21)):
            raise ValueError(f"points span more than 2^21 voxels of {voxel_m} m")
        keys |= cells << shift
    return keys


def voxel_groups(
    points: NDArray[np.float64], voxel_m: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Each of ``points`` (N, 3)'s voxel of edge ``voxel_m``, numbered in ascending key order
    (as ``np.unique`` numbers them), and each voxel's point count. Found by a stable sort of
    the keys: points come in the camera's scan order, whose runs a stable sort merges in half
    the time of ``np.unique``'s quicksort (a station's soil sample 3.7 -> 1.8 ms)."""
    keys = voxel_keys(points, voxel_m)
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    first = np.empty(len(keys), dtype=bool)
    first[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
    group = np.empty(len(keys), dtype=np.intp)
    group[order] = np.cumsum(first) - 1
    counts = np.diff(np.append(np.flatnonzero(first), len(keys)))
    return group, counts


def voxel_mean(cloud: Cloud, voxel_m: float) -> Cloud:
    """One point per occupied voxel: the mean position and mean colour of its points, a mixed
    pixel (:attr:`Cloud.mixed`) where all of them are."""
    if len(cloud) == 0:
        return cloud
    group, counts = voxel_groups(cloud.points, voxel_m)
    points = _group_means(group, cloud.points, counts)
    colors = np.rint(_group_means(group, cloud.colors, counts)).astype(np.uint8)
    mixed = None
    if cloud.mixed is not None:
        mixed = np.bincount(group, weights=cloud.mixed, minlength=len(counts)) == counts
    return Cloud(points, colors, mixed)


def voxel_mean_points(points: NDArray[np.float64], voxel_m: float) -> NDArray[np.float64]:
    """(M, 3) the mean of ``points`` (N, 3) in each occupied voxel: :func:`voxel_mean`'s
    positions without the colours (the soil samples, the registration's steady points)."""
    if len(points) == 0:
        return np.empty((0, 3))
    group, counts = voxel_groups(points, voxel_m)
    return _group_means(group, points, counts)


def _group_means(
    group: NDArray[np.intp], values: NDArray[np.generic], counts: NDArray[np.intp]
) -> NDArray[np.float64]:
    columns = [
        np.bincount(group, weights=values[:, i], minlength=len(counts))
        for i in range(values.shape[1])
    ]
    return np.stack(columns, axis=1) / counts[:, None]


@dataclass(frozen=True)
class FilteredStation:
    """A station's plant points (green, above the ground, voxel means) and a sparse sample of
    its soil, both in the field frame, with the points each filter kept; ``steady``: the same
    two at their blocks' median depths (``scans.block_median_depths``), as the registration
    takes them (``None``: ``plants`` and ``soil_m`` themselves)."""

    plants: Cloud
    soil_m: NDArray[np.float64]
    kept: dict[str, int]
    steady: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    continued: Cloud = field(default_factory=Cloud.empty)
    """The points of the leaves' surfaces continued past their green
    (``scans.continued_surfaces``) that stand ``pass_through_continued_min_m`` clear of the
    local ground, voxel means: kept apart from ``plants``, they join the plants they continue
    once these are found."""

    def registration_points(self, include_soil: bool) -> NDArray[np.float64]:
        """(N, 3) the points the registration aligns: the plants, and the soil when
        ``include_soil``, steady where known."""
        plants, soil = self.steady or (self.plants.points, self.soil_m)
        return np.concatenate([plants, soil]) if include_soil else plants


def filter_station(
    green_field: Cloud,
    soil_field: Cloud,
    settings: FilterSettings,
    soil_band_m: float,
    soil_voxel_m: float,
    by_geometry: bool = False,
    steady: tuple[Cloud, Cloud] | None = None,
    continued: Cloud | None = None,
) -> FilteredStation:
    """Pass-through on a levelled station's green points (z is the height above the ground),
    then voxel means; the soil points near the ground are kept as a sparse sample.

    ``by_geometry``: ``green_field`` holds every point (no colour to tell plants by); the
    plants are the points standing clear of the local ground (see
    :func:`~fieldapp.recon.geometry_split.plants_above_local_ground`) and the soil sample the
    points that do not.

    ``steady``: the green points and the soil sample again at their blocks' median depths,
    filtered the same way for the registration; by geometry, point for point the same as
    ``green_field`` and ``soil_field``: what tells the plants from the soil, and the soil
    sample the registration takes.

    ``continued``: the points of the leaves' surfaces that colour did not call green
    (``scans.continued_surfaces``), kept apart where they stand
    ``pass_through_continued_min_m`` clear of the local ground.
    """
    steady_points = None
    steady_soil = None
    continued_kept = Cloud.empty()
    if by_geometry:
        # told apart on the steady points where given (the same points, point for point): in
        # the sun the soil's noise stands clear of its ground and joined the plants
        # (RECONSTRUCTION.md, "Sunlight"); the plants are measured on their own depths
        told = steady or (green_field, soil_field)
        is_plant, height_m, soil_height_m = plants_above_local_ground(
            told[0].points,
            told[1].points,
            soil_band_m,
            None if steady is None else green_field.points,
            settings.geometry_plant_min_m,
        )
        kept = {"geometry": int(is_plant.sum())}
        local_soil = soil_height_m < LOCAL_SOIL_M
        plants = green_field.select(is_plant & (height_m <= settings.pass_through_max_m))
        soil_field = soil_field.select(local_soil)
        if steady is not None:
            steady_soil = _soil_sample(steady[1].points[local_soil], soil_band_m, soil_voxel_m)
    else:
        kept = {"excess_green": len(green_field)}
        # over the local ground, not the plane: real soil has clods, ridges and furrows (the
        # simulated soil too), and "1 cm above the plane" let through green lying on a rise of
        # it: weeds, moss, and the soil beside a leaf that took its colour where the colour
        # image is registered a pixel or two off (RECONSTRUCTION.md, "Colour a pixel or two
        # off the depth")
        ground = station_ground(soil_field.points, soil_band_m)  # once for both copies
        # a point not green by its own colour (not_green) stands further clear: the same
        # colours in both copies
        least = np.where(
            not_green(green_field.colors),
            settings.pass_through_dull_min_m,
            settings.pass_through_min_m,
        )
        passed = _passes_through(green_field.points, least, ground, settings)
        if steady is not None:
            # point for point the same pixels at their blocks' median depths: a point passes
            # where both stand clear (in the sun the soil's noise lifts a pixel of green soil,
            # not its block)
            passed &= _passes_through(steady[0].points, least, ground, settings)
            steady_points = (
                voxel_mean_points(steady[0].points[passed], settings.voxel_size_m),
                _soil_sample(steady[1].points, soil_band_m, soil_voxel_m),
            )
        plants = green_field.select(passed)
        if continued is not None and len(continued):
            least_m = settings.pass_through_continued_min_m
            continued = continued.select(
                _passes_through(continued.points, least_m, ground, settings)
            )
            continued_kept = voxel_mean(continued, settings.voxel_size_m)
    kept["pass_through"] = len(plants)
    plants = voxel_mean(plants, settings.voxel_size_m)
    kept["voxel_mean"] = len(plants)
    if steady_soil is not None:
        # the registration takes the plants' own voxel means: the plain medians of every
        # pixel (not held to a leaf's surface, which is not known when they are taken) blur
        # the leaves (a shaded plot's stations 1.4 -> 2.7 mm off)
        steady_points = (plants.points, steady_soil)
    soil = _soil_sample(soil_field.points, soil_band_m, soil_voxel_m)
    if len(continued_kept):
        kept["continued"] = len(continued_kept)
    return FilteredStation(plants, soil, kept, steady_points, continued_kept)


def not_green(colors: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """(N,) which of ``colors`` (N, 3) are not green by their own colour: excess green under
    :data:`~fieldapp.recon.exg.NOT_GREEN_EXG` (a leaf's rim the colour step's rim rules kept
    beside green, or the soil they grew into), or no colour at all
    (:data:`~fieldapp.recon.exg.NO_COLOUR_SUM`: libfreenect2's holes and dark pixels, which
    their own rule grows along a leaf; near the ground they are mostly the soil beside a stem
    or a leaf that the colour camera, 5.2 cm aside, does not see)."""
    return ~has_colour(colors) | (excess_green(colors) < NOT_GREEN_EXG)


def _passes_through(
    points_m: NDArray[np.float64],
    least_m: NDArray[np.float64] | float,
    ground: LocalGround,
    settings: FilterSettings,
) -> NDArray[np.bool_]:
    """(N,) which points ``points_m`` (N, 3) stand ``least_m`` (each its own, (N,), or one for
    all) clear of the local ``ground`` and at most ``pass_through_max_m`` above the plane."""
    clear = height_above(ground, points_m)
    passes: NDArray[np.bool_] = (clear >= least_m) & (  # off the soil
        points_m[:, 2] <= settings.pass_through_max_m  # above the plane
    )
    return passes


def _soil_sample(
    points: NDArray[np.float64], soil_band_m: float, soil_voxel_m: float
) -> NDArray[np.float64]:
    """The soil ``points`` (N, 3) within ``soil_band_m`` of the plane, voxel means."""
    return voxel_mean_points(points[np.abs(points[:, 2]) <= soil_band_m], soil_voxel_m)


def remove_outliers(
    cloud: Cloud, settings: FilterSettings, workers: int = 1
) -> tuple[Cloud, dict[str, int]]:
    """Statistical then radius outlier removal on the fused plant cloud of the plot (every
    station's view of a leaf together: a real surface has support, a stray point has none).
    Returns the cloud kept and the points kept by each filter. Both filters are answered by
    one k-nearest-neighbour search (:func:`outlier_masks`)."""
    kept, _, counts = split_outliers(cloud, settings, workers, doubtful=False)
    return kept, counts


def split_outliers(
    cloud: Cloud, settings: FilterSettings, workers: int = 1, doubtful: bool = True
) -> tuple[Cloud, Cloud, dict[str, int]]:
    """:func:`remove_outliers`, and the points it removes that are only *doubtful*: those the
    statistical filter keeps with its floor at ``sor_doubtful_distance_m`` and that then pass
    the radius filter among its inliers so kept (``FilterSettings.sor_doubtful_distance_m``;
    none without ``doubtful``). Returns (kept, doubtful, the points kept by each filter and
    the doubtful count)."""
    loose = settings.sor_doubtful_distance_m if doubtful else None
    masks = outlier_masks(
        cloud.points,
        settings.sor_neighbors,
        settings.sor_std_ratio,
        settings.ror_radius_m,
        settings.ror_min_points,
        workers,
        settings.sor_min_distance_m,
        loose,
    )
    counts = {
        "statistical_outliers": int(masks.statistical.sum()),
        "radius_outliers": int(masks.radius.sum()),
    }
    if doubtful:
        counts["doubtful_found"] = int(masks.doubtful.sum())
    return cloud.select(masks.radius), cloud.select(masks.doubtful), counts


@dataclass(frozen=True)
class OutlierMasks:
    """(N,) masks of :func:`outlier_masks`: the statistical filter's inliers, those that
    also pass the radius filter among them (the points kept), and the doubtful points."""

    statistical: NDArray[np.bool_]
    radius: NDArray[np.bool_]
    doubtful: NDArray[np.bool_]


def outlier_masks(
    points: NDArray[np.float64],
    neighbors: int,
    std_ratio: float,
    radius_m: float,
    min_points: int,
    workers: int = 1,
    min_distance_m: float = 0.0,
    doubtful_distance_m: float | None = None,
) -> OutlierMasks:
    """Masks (N,) of the inliers of :func:`statistical_outliers` on ``points`` (N, 3) and of
    those that then also pass :func:`radius_outliers` among the statistical inliers: the same
    masks as the two filters run one after the other, from one tree and one query. With
    ``doubtful_distance_m``, the doubtful points too: not kept, but kept by the two filters
    with the statistical floor at ``doubtful_distance_m`` instead of ``min_distance_m``.

    The ``neighbors`` + 1 nearest points, sorted by distance, give each point's mean distance
    (SOR) and its nearest neighbours within ``radius_m`` (ROR). Of those only the nearest
    ``min_points`` + :data:`ROR_SPARE` are kept, with how many there are: a point that has
    ``min_points`` statistical inliers among the kept ones passes; one whose neighbours within
    the radius were all kept fails; the few others (a point among outliers, or whose every one
    of the nearest lies within the radius) are counted again by a radius query among the
    inliers. The same masks, for a sixth of the memory.
    """
    n = len(points)
    if n == 0:
        none = np.ones(0, dtype=bool)
        return OutlierMasks(none, none, np.zeros(0, dtype=bool))
    tree = _Neighbours(points, workers)
    k = min(neighbors + 1, n)
    # The query in blocks, keeping of each block only what the filters need: the mean
    # distance, and the nearest neighbours within the radius as int32 (-1 beyond it, and for
    # the point itself). Whole, the (N, k) distances and int64 indices were 576 bytes per
    # point, the peak of a large plot's run; all k neighbours within the radius, 144.
    kept = min(k, min_points + ROR_SPARE + 1)  # one more: the point itself is among them
    mean_distance = np.empty(n)
    near_index = np.empty((n, kept), dtype=np.int32)
    # whether the neighbours kept may not settle a point's count: more of the k lie within the
    # radius than were kept, or every one of the k does (more may lie beyond them)
    unsettled = np.empty(n, dtype=bool)
    for start in range(0, n, OUTLIER_QUERY_BLOCK):
        block = slice(start, min(start + OUTLIER_QUERY_BLOCK, n))
        distances, index = tree.query(points[block], k)
        mean_distance[block] = distances[:, 1:].mean(axis=1) if k > 1 else 0.0
        itself = index == np.arange(block.start, block.stop)[:, None]
        near = (distances <= radius_m) & ~itself
        near_index[block] = np.where(near, index, -1)[:, :kept]  # nearest first
        unsettled[block] = near[:, kept:].any(axis=1) | ((distances[:, -1] <= radius_m) & (k < n))

    def statistical(floor_m: float) -> NDArray[np.bool_]:
        if n <= neighbors:
            return np.ones(n, dtype=bool)
        return mean_distance <= sor_limit(mean_distance, std_ratio, floor_m)

    def enough(inliers: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """(N,) which points have ``min_points`` of the ``inliers`` within the radius."""
        count = np.zeros(n, dtype=np.int64)
        for start in range(0, n, OUTLIER_QUERY_BLOCK):
            rows = near_index[start : start + OUTLIER_QUERY_BLOCK]
            count[start : start + len(rows)] = ((rows >= 0) & inliers[rows]).sum(axis=1)
        unsure = np.flatnonzero(inliers & (count < min_points) & unsettled)
        if len(unsure):
            found = cKDTree(points[inliers]).query_ball_point(
                points[unsure], radius_m, return_length=True
            )
            count[unsure] = found - 1
        return count >= min_points

    inliers = statistical(min_distance_m)
    radius = inliers & enough(inliers)
    doubtful = np.zeros(n, dtype=bool)
    if doubtful_distance_m is not None and doubtful_distance_m > min_distance_m:
        loose = statistical(doubtful_distance_m)
        if (loose & ~inliers).any():
            doubtful = loose & ~radius & enough(loose)
    return OutlierMasks(inliers, radius, doubtful)


class _Neighbours:
    """The nearest of ``points`` (N, 3) float64 to query points, through pykdtree on
    ``workers`` OpenMP threads: the same distances as scipy's cKDTree (sums of squares in the
    same order), for two thirds of its CPU with the outlier filters' 36 neighbours."""

    def __init__(self, points: NDArray[np.float64], workers: int) -> None:
        # Its OpenMP reads OMP_WAIT_POLICY when it loads: threads that sleep when idle (as
        # pairwise.py sets it for small_gicp), also in a process that registers nothing.
        os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
        from pykdtree.kdtree import KDTree

        _openmp_threads(workers)
        self.tree = KDTree(np.ascontiguousarray(points, dtype=np.float64))

    def query(
        self, queries: NDArray[np.float64], k: int
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """(Q, k) distances of the ``k`` nearest points, nearest first, and (Q, k) their
        indices, for each query point (Q, 3)."""
        distances, index = self.tree.query(np.ascontiguousarray(queries), k=k)
        return distances.reshape(-1, k), index.reshape(-1, k).astype(np.int64)


def _openmp_threads(threads: int) -> None:
    """pykdtree's queries on ``threads`` threads. Its wheel brings its own libgomp, which reads
    ``OMP_NUM_THREADS`` once when it loads; its ``omp_set_num_threads`` sets the count for the
    calling thread's next queries. A pykdtree built against the system's OpenMP keeps that
    one's count (the results are the same on any count)."""
    libraries = _pykdtree_openmp()
    for library in libraries:
        library.omp_set_num_threads(threads)
    if log.isEnabledFor(logging.DEBUG):  # `fieldapp -v`: the count read back, so it took effect
        for library in libraries:
            name = Path(library._name).name
            log.debug("pykdtree's OpenMP: %s on %d threads", name, library.omp_get_max_threads())


@cache
def _pykdtree_openmp() -> tuple[ctypes.CDLL, ...]:
    """The OpenMP libraries pykdtree's wheel brings (none when built against the system's),
    found once per process."""
    import pykdtree

    folder = Path(pykdtree.__file__).parent.parent / "pykdtree.libs"
    libraries = tuple(ctypes.CDLL(str(library)) for library in sorted(folder.glob("libgomp*")))
    if not libraries:  # said: a bundle that lost pykdtree's libgomp would look just like this
        log.debug("pykdtree's OpenMP: no libgomp in %s, OMP_NUM_THREADS sets its threads", folder)
    return libraries
