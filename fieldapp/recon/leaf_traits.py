"""Traits of one leaf and of the stem, from a plant's organs (definitions in docs/TRAITS.md).

A leaf's **midrib** is traced through the leaf's points: geodesic distance (shortest paths
along 1.2 cm links) from where the leaf leaves the stem's cylinder, the centroid of every 1 cm
level set, and the farthest point (the tip). The **collar** is where the midrib, extended
back along its first centimetres, meets the stem's surface. The leaf's **cross-sections** are
the 1 cm level sets of the geodesic distance from the tip (seen from the tip, the base of a
leaf that hugs the stem is cut across, not along): each section's points, seen along the
leaf, give its **width**, the length of the section's profile (a folded blade is measured
flattened, as with a ruler); the **area** is the width integrated from the tip over the
midrib's length."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from fieldapp.recon.organs import StemAxis, pair_graph, pair_lengths, voxel_means

LINK_M = 0.012
LEVEL_M = 0.01
"""Geodesic links and the spacing of the level sets along the leaf."""

SOURCE_BAND_M = 0.01
"""The leaf's base: its points within this of its point nearest to the stem's axis."""

COLLAR_FIT_M = 0.05
MAX_EXTENSION_M = 0.06
"""The midrib is extended back to the stem (at most :data:`MAX_EXTENSION_M`) along the parabola
through its first :data:`COLLAR_FIT_M`."""

BASE_CHORD_M = 0.05
"""Angle from the stem: chord from the collar to the midrib point this far along it."""

EDGE_QUANTILE = 2.0
"""A cross-section's span: between this percentile and its complement (scaled up)."""


@dataclass(frozen=True)
class LeafTraits:
    """One leaf; ``leaf_id`` from the bottom; azimuth in the field frame (from +x towards +y)."""

    leaf_id: int
    length_m: float
    max_width_m: float
    area_m2: float
    angle_from_stem_deg: float
    azimuth_deg: float
    insertion_height_m: float
    midrib_m: NDArray[np.float64]
    """(P, 3) the traced midrib, collar first."""


def measure_leaf(
    points_m: NDArray[np.float64], axis: StemAxis, stem_radius_m: float, leaf_id: int
) -> LeafTraits:
    """Traits of one leaf from its points (M, 3), the stem's axis and radius."""
    whole = [np.arange(len(points_m))]
    return measure_leaves(points_m, whole, axis, stem_radius_m, first_id=leaf_id)[0]


def measure_leaves(
    points_m: NDArray[np.float64],
    leaves: list[NDArray[np.intp]],
    axis: StemAxis,
    stem_radius_m: float,
    first_id: int = 1,
) -> list[LeafTraits]:
    """Traits of each leaf of a plant: ``leaves`` the indices of each leaf's points (non-empty,
    disjoint) into the plant's points (N, 3), numbered from ``first_id``; the stem's axis and
    radius. The leaves are measured together: one graph of all of them (each its own
    component), one shortest-path search per question for all, every cross-section of every
    leaf in one set of array operations. Measured a leaf at a time, the calls cost more than
    the work (95 leaves: 0.46 s CPU)."""
    batch = _Batch.of(points_m, leaves)
    points = batch.points
    _along, radial = axis.split(points)
    lowest = np.minimum.reduceat(radial, batch.starts)
    graph = LeafGraph.of(points, batch.leaf)
    distance = graph.geodesic_m(np.flatnonzero(radial <= lowest[batch.leaf] + SOURCE_BAND_M))
    centres = _section_centres(points, batch, distance)
    tips = batch.starts + np.array([np.argmax(d) for d in np.split(distance, batch.starts[1:])])
    from_tip, width = _widths_from_tip(points, batch, graph, tips)
    measured = []
    for k, (centres_m, tip) in enumerate(zip(centres, points[tips], strict=True)):
        extension = _collar(centres_m, axis, stem_radius_m)
        collar = extension[0]
        midrib = np.vstack([extension, centres_m, tip])
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(midrib, axis=0), axis=1))])
        measured.append(
            LeafTraits(
                leaf_id=first_id + k,
                length_m=float(arc[-1]),
                max_width_m=float(width[k].max()) if len(width[k]) else 0.0,
                area_m2=_area_m2(from_tip[k], width[k], float(arc[-1])),
                angle_from_stem_deg=angle_from_axis_deg(midrib, axis.direction),
                azimuth_deg=azimuth_deg(tip - collar),
                insertion_height_m=float(collar[2] - axis.foot_m[2]),
                midrib_m=midrib,
            )
        )
    return measured


@dataclass(frozen=True)
class _Batch:
    """The leaves of a plant one after the other: ``points`` (M, 3), ``leaf`` (M,) the leaf of
    each (0-based), ``starts`` (L,) where each leaf's points begin."""

    points: NDArray[np.float64]
    leaf: NDArray[np.intp]
    starts: NDArray[np.intp]

    @classmethod
    def of(cls, points_m: NDArray[np.float64], leaves: list[NDArray[np.intp]]) -> _Batch:
        sizes = np.array([len(leaf) for leaf in leaves])
        if len(leaves) == 0 or sizes.min() == 0:
            raise ValueError("every leaf needs points")
        leaf = np.repeat(np.arange(len(leaves)), sizes)
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        return cls(points_m[np.concatenate(leaves)], leaf, starts)


def _level_sets(
    batch: _Batch, distance: NDArray[np.float64]
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """The :data:`LEVEL_M` level sets of ``distance`` (M,) in every leaf, leaf by leaf, nearest
    first: the order of the points that puts each set's points together (in their leaf's
    order), and per set its leaf, its level and its number of points."""
    levels = np.floor(distance / LEVEL_M).astype(np.intp)
    key = batch.leaf * (int(levels.max()) + 1) + levels
    order = np.argsort(key, kind="stable")
    keys, counts = np.unique(key[order], return_counts=True)
    return order, keys // (int(levels.max()) + 1), keys % (int(levels.max()) + 1), counts


def _set_means(
    points_m: NDArray[np.float64], order: NDArray[np.intp], counts: NDArray[np.intp]
) -> NDArray[np.float64]:
    """(S, 3) the mean of each set of points: ``points_m[order]`` split into sets of ``counts``
    (summed in order: the same value as each set's ``mean(axis=0)``)."""
    group = np.repeat(np.arange(len(counts)), counts)
    sums = [np.bincount(group, points_m[order, i], len(counts)) for i in range(3)]
    return np.stack(sums, axis=1) / counts[:, None]


def _section_centres(
    points_m: NDArray[np.float64], batch: _Batch, distance: NDArray[np.float64]
) -> list[NDArray[np.float64]]:
    """Per leaf, the centres (K, 3) of its level sets of ``distance`` (from the stem) of at
    least 3 points, nearest first; the leaf's mean point (1, 3) when none has."""
    order, leaf, _, counts = _level_sets(batch, distance)
    centres = _set_means(points_m, order, counts)
    whole = _set_means(points_m, np.arange(len(points_m)), np.bincount(batch.leaf))
    return [
        centres[(leaf == k) & (counts >= 3)]
        if np.any((leaf == k) & (counts >= 3))
        else whole[k : k + 1]
        for k in range(len(batch.starts))
    ]


def _widths_from_tip(
    points_m: NDArray[np.float64], batch: _Batch, graph: LeafGraph, tips: NDArray[np.intp]
) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64]]]:
    """Per leaf, its flattened width (running median) across each :data:`LEVEL_M` level set
    of the geodesic distance from its tip (``tips``: (L,) one point per leaf): (K,) the level
    sets' middle distances from the tip and (K,) their widths, tip first. Seen from the tip
    every level set is a cross-section down to the base; seen from the stem, the base of a
    leaf hugging the stem (a strip along it, all at one distance from the stem) would be one
    "section" as long as the strip."""
    order, leaf, level, counts = _level_sets(batch, graph.geodesic_m(tips))
    centres = _set_means(points_m, order, counts)
    index = np.arange(len(counts))
    first = np.searchsorted(leaf, leaf, side="left")
    last = np.searchsorted(leaf, leaf, side="right") - 1
    tangents = centres[np.maximum(index - 1, first)] - centres[np.minimum(index + 1, last)]
    widths = section_widths_m(points_m[order], counts, tangents)
    ends = np.searchsorted(leaf, np.arange(len(batch.starts) + 1))
    from_tip = LEVEL_M * (level + 0.5).astype(np.float64)
    return (
        [from_tip[a:b] for a, b in itertools.pairwise(ends)],
        [_running_median(widths[a:b]) for a, b in itertools.pairwise(ends)],
    )


def _area_m2(
    from_tip_m: NDArray[np.float64], width_m: NDArray[np.float64], length_m: float
) -> float:
    """One side of the blade: the widths (K,) at ``from_tip_m`` (K,) along the leaf from its
    tip (none at the tip itself), integrated over the midrib's ``length_m``, the last width
    held to the collar."""
    at = np.concatenate([[0.0], from_tip_m])
    profile = np.concatenate([[0.0], width_m])
    grid = np.append(at[at < length_m], length_m)
    return float(np.trapezoid(np.interp(grid, at, profile), grid))


@dataclass(frozen=True)
class LeafGraph:
    """Leaves' points linked for geodesic distances: ``means_m`` (V, 3) the means of their
    voxels (:func:`fieldapp.recon.organs.voxel_means`, a leaf's voxels its own), ``inverse``
    (M,) each point's voxel, ``leaf`` (V,) each voxel's leaf, ``links`` (V, V) sparse, the
    lengths of the links shorter than :data:`LINK_M` within a leaf."""

    means_m: NDArray[np.float64]
    inverse: NDArray[np.intp]
    leaf: NDArray[np.intp]
    links: csr_matrix

    @classmethod
    def of(cls, points_m: NDArray[np.float64], leaf: NDArray[np.intp] | None = None) -> LeafGraph:
        """The graph of leaves' points (M, 3), ``leaf`` (M,) the leaf of each (default: one)."""
        leaf = np.zeros(len(points_m), dtype=np.intp) if leaf is None else leaf
        means, inverse = voxel_means(points_m, groups=leaf)
        voxel_leaf = np.zeros(len(means), dtype=np.intp)
        voxel_leaf[inverse] = leaf
        starts = np.searchsorted(voxel_leaf, np.arange(voxel_leaf[-1] + 2))
        pairs = np.concatenate(  # a tree per leaf: a leaf's voxels are one slice of them
            [
                cKDTree(means[a:b]).query_pairs(LINK_M, output_type="ndarray") + a
                for a, b in itertools.pairwise(starts)
            ]
        )
        links = pair_graph(pairs, len(means), pair_lengths(means, pairs) + 1e-9)
        return cls(means, inverse, voxel_leaf, links)

    def geodesic_m(self, sources: NDArray[np.intp]) -> NDArray[np.float64]:
        """(M,) every point's shortest distance from any of the points ``sources`` of its leaf
        along the links; a voxel the links do not reach (a piece cut off by a gap) gets its
        leaf's nearest reached voxel's distance plus the straight gap."""
        starts = np.unique(self.inverse[sources])
        distance = dijkstra(self.links, directed=False, indices=starts, min_only=True)
        for leaf in np.unique(self.leaf[~np.isfinite(distance)]):
            mine = self.leaf == leaf
            reached, unreached = mine & np.isfinite(distance), mine & ~np.isfinite(distance)
            gap, nearest = cKDTree(self.means_m[reached]).query(self.means_m[unreached])
            distance[unreached] = distance[reached][nearest] + gap
        return distance[self.inverse]  # type: ignore[no-any-return]


def geodesic_m(points_m: NDArray[np.float64], sources: NDArray[np.intp]) -> NDArray[np.float64]:
    """(M,) shortest distance of the points (M, 3) from any of ``sources`` through the leaf
    (:meth:`LeafGraph.geodesic_m`)."""
    return LeafGraph.of(points_m).geodesic_m(sources)


def _collar(
    centres_m: NDArray[np.float64], axis: StemAxis, stem_radius_m: float
) -> NDArray[np.float64]:
    """Where the midrib, extended back from its first centre, meets the stem's surface (or comes
    nearest to it), as (C, 3) points from the collar to just before the first centre. The
    extension follows the parabola (in arc length) fitted to the centres of the first
    :data:`COLLAR_FIT_M`: a leaf bends away from the stem as it goes, so a straight line through
    its first centimetres would meet the stem too low and leave it too flat."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(centres_m, axis=0), axis=1))])
    chosen = arc <= COLLAR_FIT_M
    degree = 2 if chosen.sum() >= 4 else 1
    if chosen.sum() < 2:
        return centres_m[:1]
    coefficients = np.polynomial.polynomial.polyfit(arc[chosen], centres_m[chosen], degree)
    back = -np.arange(0.0, MAX_EXTENSION_M, 0.0005)
    steps: NDArray[np.float64] = np.polynomial.polynomial.polyval(back, coefficients).T
    _, radial = axis.split(steps)
    inside = np.flatnonzero(radial <= stem_radius_m)
    end = int(inside[0]) if len(inside) else int(np.argmin(radial))
    return steps[end::-1][:-1] if end > 0 else steps[:1]


def section_widths_m(
    points_m: NDArray[np.float64], counts: NDArray[np.intp], tangents: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(S,) flattened width of each cross-section (``points_m`` (M, 3) the sections' points one
    section after the other, ``counts`` (S,) how many each has) seen along its tangent (S, 3):
    the span across it (between the 2nd and 98th percentiles, scaled to the whole span of
    evenly spread points: noise widens the extremes, not the quantiles) times the length per
    span of the parabola fitted to the section's profile (a folded blade measured flat); 0 for
    a section of fewer than 5 points. Every section at once: per section the calls would cost
    more than the work."""
    widths = np.zeros(len(counts))
    norms = np.linalg.norm(tangents, axis=1)
    chosen = np.flatnonzero((norms >= 1e-9) & (counts >= 5))
    if len(chosen) == 0:
        return widths
    rank = np.full(len(counts), -1)
    rank[chosen] = np.arange(len(chosen))
    group = np.repeat(rank, counts)
    kept = group >= 0
    group = group[kept]
    size = counts[chosen]
    q = points_m[kept] - (_sums(group, points_m[kept], len(chosen)) / size[:, None])[group]
    t = (tangents[chosen] / norms[chosen, None])[group]
    flat = q - np.sum(q * t, axis=1)[:, None] * t
    upper = flat[:, [0, 0, 0, 1, 1, 2]] * flat[:, [0, 1, 2, 1, 2, 2]]
    scatter = _sums(group, upper, len(chosen))[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]]
    _, vectors = np.linalg.eigh(scatter.reshape(-1, 3, 3))
    across = np.sum(flat * vectors[group, :, 2], axis=1)
    height = np.sum(flat * vectors[group, :, 1], axis=1)
    ordered = across[np.lexsort((across, group))]
    first = np.concatenate([[0], np.cumsum(size)[:-1]])
    edge = np.rint(EDGE_QUANTILE / 100.0 * (size - 1)).astype(np.intp)
    spans = (ordered[first + size - 1 - edge] - ordered[first + edge]) / (
        1.0 - 2.0 * edge / (size - 1)
    )
    squared = across * across
    powers = np.stack(
        [np.ones_like(across), across, squared, squared * across, squared * squared], 1
    )
    moments = _sums(group, powers, len(chosen))
    normal = moments[:, [0, 1, 2, 1, 2, 3, 2, 3, 4]].reshape(-1, 3, 3) + 1e-12 * np.eye(3)
    rhs = _sums(group, powers[:, :3] * height[:, None], len(chosen))
    curve = np.linalg.solve(normal, rhs[:, :, None])[:, :, 0]
    low, high = ordered[first], ordered[first + size - 1]
    x = low[:, None] + (high - low)[:, None] * np.linspace(0.0, 1.0, 32)
    y = curve[:, :1] + curve[:, 1:2] * x + curve[:, 2:] * x * x
    chord = high - low
    arc = np.hypot(np.diff(x, axis=1), np.diff(y, axis=1)).sum(axis=1)
    stretch = np.divide(arc, chord, out=np.ones_like(arc), where=chord > 0)
    widths[chosen] = spans * stretch
    return widths


def _sums(group: NDArray[np.intp], values: NDArray[np.float64], groups: int) -> NDArray[np.float64]:
    """(G, C) the sums of ``values`` (M, C) over each of the ``groups`` groups (``group``:
    (M,) the group of each row)."""
    return np.stack(
        [np.bincount(group, values[:, c], groups) for c in range(values.shape[1])], axis=1
    )


def _running_median(values: NDArray[np.float64], half: int = 1) -> NDArray[np.float64]:
    """``values`` (K,) through a running median of ``2 * half + 1``, the ends taking their
    nearest whole window's (a repeated end value would keep a spoilt end section): a section
    spoilt by a touching leaf or the stem's noise does not make the leaf's width."""
    size = 2 * half + 1
    if len(values) < size:
        return values
    windows = np.stack([values[i : i + len(values) - size + 1] for i in range(size)])
    middle = np.median(windows, axis=0)
    return np.concatenate([np.full(half, middle[0]), middle, np.full(half, middle[-1])])


def angle_from_axis_deg(
    midrib_m: NDArray[np.float64], axis_direction: NDArray[np.float64]
) -> float:
    """Angle between the stem's upward ``axis_direction`` (3,) and the chord from the midrib's
    first point (the collar) to its point :data:`BASE_CHORD_M` along it (P, 3)."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(midrib_m, axis=0), axis=1))])
    end = np.array([np.interp(min(BASE_CHORD_M, s[-1]), s, midrib_m[:, i]) for i in range(3)])
    chord = end - midrib_m[0]
    cosine = float(chord @ axis_direction) / max(float(np.linalg.norm(chord)), 1e-12)
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def azimuth_deg(direction: NDArray[np.float64]) -> float:
    """Azimuth of ``direction``'s horizontal part: degrees in [0, 360) from +x towards +y."""
    return float(np.degrees(np.arctan2(direction[1], direction[0])) % 360.0)


def stem_diameter_m(
    points_m: NDArray[np.float64], axis: StemAxis, cut_m: float, top_m: float
) -> float | None:
    """Median over 1 cm slices, from 5 mm above the foot to ``top_m`` along the axis, of the
    diameter of the circle fitted (least squares) to the slice's points within ``cut_m`` of the
    axis; ``None`` when no slice has enough points."""
    along, radial = axis.split(points_m)
    diameters = []
    for low in np.arange(0.005, max(top_m, 0.005), 0.01):
        chosen = (radial <= cut_m) & (along >= low) & (along < min(low + 0.01, top_m))
        if chosen.sum() >= 8:
            radius = _circle_radius(points_m[chosen, :2])
            if radius is not None and radius < cut_m:
                diameters.append(2.0 * radius)
    return float(np.median(diameters)) if diameters else None


def _circle_radius(xy: NDArray[np.float64]) -> float | None:
    """Radius of the least-squares (Kasa) circle through ``xy`` (K, 2), refitted once without
    the points farther than 3 robust deviations from it."""
    keep = np.ones(len(xy), dtype=bool)
    radius = None
    for _ in range(2):
        if keep.sum() < 5:
            return radius
        x, y = xy[keep, 0], xy[keep, 1]
        design = np.stack([x, y, np.ones_like(x)], axis=1)
        a, b, c = np.linalg.lstsq(design, x * x + y * y, rcond=None)[0]
        centre = np.array([a / 2.0, b / 2.0])
        squared = c + centre @ centre
        if squared <= 0:
            return None
        radius = float(np.sqrt(squared))
        residual = np.abs(np.linalg.norm(xy - centre, axis=1) - radius)
        keep = residual <= 3.0 * max(float(np.median(residual)) * 1.4826, 1e-4)
    return radius
