"""Plant filtering: pass-through above the ground, excess green, outlier removal, voxel means.

Cheap per-point tests (pass-through, ExG) run first, on every frame, so the neighbourhood
searches (SOR, ROR) only see the few plant points left.
"""

from __future__ import annotations

import ctypes
import logging
import os
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.geometry_split import LOW_M as LOCAL_SOIL_M
from fieldapp.recon.geometry_split import plants_above_local_ground
from fieldapp.recon.settings import FilterSettings

log = logging.getLogger(__name__)

OTSU_BINS = 256
SUM_LEVELS = 3 * 255 + 1
EXG_KEYS = 256 * SUM_LEVELS
"""Colour keys of excess green (:func:`exg_keys`): 2G - R - B over S = R + G + B is 3G / S - 1,
a function of the green level G and the sum S alone, so 196 608 keys hold every value."""
NO_KEY = EXG_KEYS
"""The key of a pixel left out (no depth): one past the last, never tallied, never green."""
OUTLIER_QUERY_BLOCK = 16_384
"""Points per neighbour query of the outlier filters: bounds its memory, and keeps each
block's arrays (5 MB) small: with 65 536 the first query's fresh 20-40 MB arrays, which numpy
asks the kernel to back with huge pages, cost 0.3-0.4 s of system time in page faults
(compaction), as much as the rest of the stage."""
VALLEY_SMOOTHING_BINS = 5
MIN_GREEN_CONTRAST = 0.1
"""Least difference of the mean ExG of Otsu's two classes for colour to separate plants: green
leaves on soil differ by 0.3-0.5, a grey or constant image by less than 0.05."""

MIN_SOIL_SHARE = 0.01
"""Least share of a station's measured pixels a set ExG threshold must leave as soil for the
soil sample (levelling, local ground, registration): seedling plots leave 99 %, a threshold
of -1 (every colour, as for white reference spheres among plants) leaves none."""

NO_COLOUR = "no colour"
NO_GREEN_CONTRAST = "colour has no green contrast"
NO_SOIL_LEFT = "the excess-green threshold leaves no soil"


@dataclass(frozen=True)
class Separation:
    """How a station's plants are told from the soil: ``"colour"`` (excess green) or
    ``"geometry"`` (height above the local ground, connectivity), and why geometry."""

    method: str
    reason: str = ""

    @property
    def by_geometry(self) -> bool:
        return self.method == "geometry"

    def describe(self) -> str:
        """One line for the report and the CLI."""
        if self.by_geometry:
            return f"plants separated by geometry: {self.reason}"
        return "plants separated by colour (excess green)"


BY_COLOUR = Separation("colour")


def green_contrast(
    exg: NDArray[np.float64],
    weights: NDArray[np.int64] | None = None,
    threshold: float | None = None,
) -> float:
    """The difference of the mean ExG (N,) of the classes either side of Otsu's threshold
    (``threshold`` when already known); 0 for a constant image. ``weights`` (N,): how many
    pixels have each value (see :func:`otsu_threshold`; default one each)."""
    if len(exg) == 0:
        return 0.0
    weights = np.ones(len(exg), dtype=np.int64) if weights is None else weights
    high = exg > (otsu_threshold(exg, weights) if threshold is None else threshold)
    count_high, count = int(weights[high].sum()), int(weights.sum())
    if count_high == 0 or count_high == count:
        return 0.0
    weighted = exg * weights
    return float(weighted[high].sum() / count_high - weighted[~high].sum() / (count - count_high))


def choose_separation(
    exg: NDArray[np.float64] | None,
    weights: NDArray[np.int64] | None = None,
    otsu: float | None = None,
) -> Separation:
    """Colour when every capture has a colour image (``exg`` (N,): the ExG of the measured
    pixels, or its distinct values and their ``weights``; ``otsu``: their Otsu threshold when
    already known) with green contrast, else geometry, saying why."""
    if exg is None:
        return Separation("geometry", NO_COLOUR)
    if green_contrast(exg, weights, otsu) < MIN_GREEN_CONTRAST:
        return Separation("geometry", NO_GREEN_CONTRAST)
    return BY_COLOUR


def keep_soil(
    separation: Separation,
    exg: NDArray[np.float64],
    threshold: float,
    weights: NDArray[np.int64] | None = None,
) -> Separation:
    """``separation``, or geometry when the colour ``threshold`` calls (nearly) every measured
    pixel (ExG (N,), or distinct values and their ``weights``) green: with no soil pixel the
    station has no ground to be levelled on and registration only the points above an
    unlevelled ground."""
    if separation.by_geometry or len(exg) == 0:
        return separation
    weights = np.ones(len(exg), dtype=np.int64) if weights is None else weights
    if int(weights[exg <= threshold].sum()) < MIN_SOIL_SHARE * int(weights.sum()):
        return Separation("geometry", NO_SOIL_LEFT)
    return separation


def pass_through(height_m: NDArray[np.float64], min_m: float, max_m: float) -> NDArray[np.bool_]:
    """Mask of the points whose height above the ground (N,) is within [min_m, max_m]."""
    return (height_m >= min_m) & (height_m <= max_m)


def excess_green(colors: NDArray[np.uint8]) -> NDArray[np.float64]:
    """ExG = 2g - r - b on chromaticity-normalised colour (r = R / (R + G + B)...), (N,) in
    [-1, 2]; black pixels get 0. The sums are exact in int16, so the one float64 division
    gives the same values as float64 arithmetic throughout, at a seventh of its cost."""
    r, g, b = (colors[:, channel].astype(np.int16) for channel in range(3))
    total = r + g + b
    total[total == 0] = 1
    return (2 * g - r - b) / total


def exg_keys(colors: NDArray[np.uint8]) -> NDArray[np.int32]:
    """(N,) int32: the key ``G * 766 + S`` of each colour (N, 3) uint8 RGB, which fixes its
    excess green (:func:`exg_of_keys`). Cheaper than the ExG itself, and a station's pixels
    are then tallied (``np.bincount``) over :data:`EXG_KEYS` values instead of histogrammed
    as floats."""
    keys = np.multiply(colors[:, 1], SUM_LEVELS, dtype=np.int32)
    total = np.add(colors[:, 0], colors[:, 1], dtype=np.int32)
    total += colors[:, 2]
    keys += total
    return keys


@cache
def exg_of_keys() -> NDArray[np.float64]:
    """(EXG_KEYS,) float64: the excess green of each key of :func:`exg_keys`, bit for bit
    :func:`excess_green`'s value for the colours of that key (read-only)."""
    green, total = np.divmod(np.arange(EXG_KEYS, dtype=np.int64), SUM_LEVELS)
    difference = 3 * green - total  # 2G - R - B
    total[total == 0] = 1
    table = difference / total
    table.flags.writeable = False
    return table


def exg_tally(keys: NDArray[np.int32]) -> NDArray[np.int64]:
    """(EXG_KEYS,) int64: how many of the pixels ``keys`` (N,) (see :func:`exg_keys`; those
    of :data:`NO_KEY` left out) have each key."""
    return np.bincount(keys, minlength=NO_KEY + 1)[:EXG_KEYS]


def exg_values(tally: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The distinct excess-green values (M,) of a :func:`exg_tally` and how many pixels have
    each (M,) int64, for :func:`otsu_threshold`, :func:`choose_separation` and
    :func:`keep_soil`. Two keys may share a value (the same ratio): it is then listed twice,
    which changes no histogram, count or mean."""
    present = np.flatnonzero(tally)
    return exg_of_keys()[present], tally[present]


def otsu_threshold(values: NDArray[np.float64], weights: NDArray[np.int64] | None = None) -> float:
    """Otsu's threshold of ``values`` (N,), placed in the valley between the two classes.
    With ``weights`` (N,) int64, positive, ``values[i]`` counts ``weights[i]`` times: the same
    threshold, bit for bit, as of the values repeated (a station's pixels, tallied by colour).

    Otsu's cut maximises the between-class variance; its two class means bracket the valley of
    the histogram. The threshold returned is the middle of the first lowest run of bins between
    the means: the same cut as Otsu's on a continuous histogram, and on a gappy one (soil, then
    a small class of yellow-green stems, then leaves) it does not split the small class off
    with the soil.
    """
    if len(values) == 0:
        raise ValueError("Otsu's threshold of no values")
    low, high = float(values.min()), float(values.max())
    if high - low < 1e-12:
        return high
    counts, edges = np.histogram(values, bins=OTSU_BINS, range=(low, high), weights=weights)
    centres = (edges[:-1] + edges[1:]) / 2.0
    weight_low = np.cumsum(counts)
    weight_high = weight_low[-1] - weight_low
    sum_low = np.cumsum(counts * centres)
    mean_low = sum_low / np.maximum(weight_low, 1)
    mean_high = (sum_low[-1] - sum_low) / np.maximum(weight_high, 1)
    between = weight_low * weight_high * (mean_low - mean_high) ** 2
    cut = int(np.argmax(between))
    return _valley(counts, edges, mean_low[cut], mean_high[cut])


def _valley(
    counts: NDArray[np.intp], edges: NDArray[np.float64], mean_low: float, mean_high: float
) -> float:
    """The middle of the first run of least-populated bins (after a light smoothing, so a
    stray empty bin in a tail is no valley) with centres in (mean_low, mean_high)."""
    centres = (edges[:-1] + edges[1:]) / 2.0
    inside = np.flatnonzero((centres > mean_low) & (centres < mean_high))
    if len(inside) == 0:
        return float((mean_low + mean_high) / 2.0)
    smooth = np.convolve(counts, np.ones(VALLEY_SMOOTHING_BINS), mode="same")
    lowest = inside[smooth[inside] == smooth[inside].min()]
    run_end = lowest[0]
    while run_end + 1 in lowest:
        run_end += 1
    return float((edges[lowest[0]] + edges[run_end + 1]) / 2.0)


def statistical_outliers(
    points: NDArray[np.float64], neighbors: int, std_ratio: float, workers: int = 1
) -> NDArray[np.bool_]:
    """Mask of the inliers of statistical outlier removal: a point is kept when its mean
    distance to its ``neighbors`` nearest neighbours is within ``std_ratio`` standard
    deviations of the cloud's average."""
    if len(points) <= neighbors:
        return np.ones(len(points), dtype=bool)
    distances, _ = cKDTree(points).query(points, k=neighbors + 1, workers=workers)
    mean_distance = distances[:, 1:].mean(axis=1)
    limit = mean_distance.mean() + std_ratio * mean_distance.std()
    return mean_distance <= limit  # type: ignore[no-any-return]


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
    """(N,) int64: one key per voxel of edge ``voxel_m`` (21 bits per axis)."""
    cells = np.floor(points / voxel_m).astype(np.int64) + (1 << 20)
    if len(cells) and (cells.min() < 0 or cells.max() >= (1 << 21)):
        raise ValueError(f"points span more than 2^21 voxels of {voxel_m} m")
    return (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]


def voxel_mean(cloud: Cloud, voxel_m: float) -> Cloud:
    """One point per occupied voxel: the mean position and mean colour of its points."""
    if len(cloud) == 0:
        return cloud
    _, inverse, counts = np.unique(
        voxel_keys(cloud.points, voxel_m), return_inverse=True, return_counts=True
    )
    inverse = inverse.ravel()
    points = _group_means(inverse, cloud.points, counts)
    colors = np.rint(_group_means(inverse, cloud.colors, counts)).astype(np.uint8)
    return Cloud(points, colors)


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
    its soil, both in the field frame, with the points each filter kept."""

    plants: Cloud
    soil_m: NDArray[np.float64]
    kept: dict[str, int]


def filter_station(
    green_field: Cloud,
    soil_field: Cloud,
    settings: FilterSettings,
    soil_band_m: float,
    soil_voxel_m: float,
    by_geometry: bool = False,
) -> FilteredStation:
    """Pass-through on a levelled station's green points (z is the height above the ground),
    then voxel means; the soil points near the ground are kept as a sparse sample.

    ``by_geometry``: ``green_field`` holds every point (no colour to tell plants by); the
    plants are the points standing clear of the local ground (see
    :func:`~fieldapp.recon.geometry_split.plants_above_local_ground`) and the soil sample the
    points that do not.
    """
    if by_geometry:
        is_plant, height_m, soil_height_m = plants_above_local_ground(
            green_field.points, soil_field.points, soil_band_m
        )
        kept = {"geometry": int(is_plant.sum())}
        plants = green_field.select(is_plant & (height_m <= settings.pass_through_max_m))
        soil_field = soil_field.select(soil_height_m < LOCAL_SOIL_M)
    else:
        kept = {"excess_green": len(green_field)}
        above = pass_through(
            green_field.points[:, 2], settings.pass_through_min_m, settings.pass_through_max_m
        )
        plants = green_field.select(above)
    kept["pass_through"] = len(plants)
    plants = voxel_mean(plants, settings.voxel_size_m)
    kept["voxel_mean"] = len(plants)
    soil = soil_field.select(np.abs(soil_field.points[:, 2]) <= soil_band_m)
    return FilteredStation(plants, voxel_mean(soil, soil_voxel_m).points, kept)


def remove_outliers(
    cloud: Cloud, settings: FilterSettings, workers: int = 1
) -> tuple[Cloud, dict[str, int]]:
    """Statistical then radius outlier removal on the fused plant cloud of the plot (every
    station's view of a leaf together: a real surface has support, a stray point has none).
    Returns the cloud kept and the points kept by each filter. Both filters are answered by
    one k-nearest-neighbour search (:func:`outlier_inliers`)."""
    statistical, radius = outlier_inliers(
        cloud.points,
        settings.sor_neighbors,
        settings.sor_std_ratio,
        settings.ror_radius_m,
        settings.ror_min_points,
        workers,
    )
    counts = {"statistical_outliers": int(statistical.sum()), "radius_outliers": int(radius.sum())}
    return cloud.select(radius), counts


def outlier_inliers(
    points: NDArray[np.float64],
    neighbors: int,
    std_ratio: float,
    radius_m: float,
    min_points: int,
    workers: int = 1,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Masks (N,) of the inliers of :func:`statistical_outliers` on ``points`` (N, 3) and of
    those that then also pass :func:`radius_outliers` among the statistical inliers: the same
    masks as the two filters run one after the other, from one tree and one query.

    The ``neighbors`` + 1 nearest points, sorted by distance, give each point's mean distance
    (SOR) and every statistical inlier within ``radius_m`` (ROR) whenever the farthest of them
    lies beyond ``radius_m``; the few points where it does not, and that have fewer than
    ``min_points`` inliers among them, are counted again by a radius query among the inliers.
    """
    n = len(points)
    if n == 0:
        return np.ones(0, dtype=bool), np.ones(0, dtype=bool)
    tree = _Neighbours(points, workers)
    k = min(neighbors + 1, n)
    # The query in blocks, keeping of each block only what the filters need: the mean
    # distance, and the neighbours within the radius as int32 (-1 beyond it, and for the
    # point itself). Whole, the (N, k) distances and int64 indices were 576 bytes per point,
    # the peak of a large plot's run.
    mean_distance = np.empty(n)
    near_index = np.empty((n, k), dtype=np.int32)
    full = np.empty(n, dtype=bool)  # every one of the k within the radius: count unsure
    for start in range(0, n, OUTLIER_QUERY_BLOCK):
        block = slice(start, min(start + OUTLIER_QUERY_BLOCK, n))
        distances, index = tree.query(points[block], k)
        mean_distance[block] = distances[:, 1:].mean(axis=1) if k > 1 else 0.0
        itself = index == np.arange(block.start, block.stop)[:, None]
        near_index[block] = np.where((distances <= radius_m) & ~itself, index, -1)
        full[block] = distances[:, -1] <= radius_m
    statistical = np.ones(n, dtype=bool)
    if n > neighbors:
        statistical = mean_distance <= mean_distance.mean() + std_ratio * mean_distance.std()
    count = np.zeros(n, dtype=np.int64)
    for start in range(0, n, OUTLIER_QUERY_BLOCK):
        rows = near_index[start : start + OUTLIER_QUERY_BLOCK]
        count[start : start + len(rows)] = ((rows >= 0) & statistical[rows]).sum(axis=1)
    unsure = np.flatnonzero(statistical & (count < min_points) & full)
    if k < n and len(unsure):
        inliers = cKDTree(points[statistical])
        count[unsure] = inliers.query_ball_point(points[unsure], radius_m, return_length=True) - 1
    return statistical, statistical & (count >= min_points)


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
