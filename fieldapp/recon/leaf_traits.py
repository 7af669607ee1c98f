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

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from fieldapp.recon.organs import StemAxis, voxel_means

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
    _along, radial = axis.split(points_m)
    sources = np.flatnonzero(radial <= radial.min() + SOURCE_BAND_M)
    graph = LeafGraph.of(points_m)
    distance = graph.geodesic_m(sources)
    sections = [s for s in _level_sets(points_m, distance) if len(s) >= 3]
    centres_m = (
        np.array([s.mean(axis=0) for s in sections])
        if sections
        else points_m.mean(axis=0, keepdims=True)
    )
    tip_index = int(np.argmax(distance))
    tip = points_m[tip_index]
    extension = _collar(centres_m, axis, stem_radius_m)
    collar = extension[0]
    midrib = np.vstack([extension, centres_m, tip])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(midrib, axis=0), axis=1))])
    from_tip, width = _widths_from_tip(points_m, graph, tip_index)
    return LeafTraits(
        leaf_id=leaf_id,
        length_m=float(arc[-1]),
        max_width_m=float(width.max()) if len(width) else 0.0,
        area_m2=_area_m2(from_tip, width, float(arc[-1])),
        angle_from_stem_deg=angle_from_axis_deg(midrib, axis.direction),
        azimuth_deg=azimuth_deg(tip - collar),
        insertion_height_m=float(collar[2] - axis.foot_m[2]),
        midrib_m=midrib,
    )


def _widths_from_tip(
    points_m: NDArray[np.float64], graph: LeafGraph, tip_index: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The leaf's flattened width (running median) across each :data:`LEVEL_M` level set of
    the geodesic distance from its tip: (K,) the level sets' middle distances from the tip and
    (K,) their widths, tip first. Seen from the tip every level set is a cross-section down to
    the base; seen from the stem, the base of a leaf hugging the stem (a strip along it, all at
    one distance from the stem) would be one "section" as long as the strip."""
    from_tip = graph.geodesic_m(np.array([tip_index]))
    sections = _level_sets(points_m, from_tip)
    levels = np.unique(np.floor(from_tip / LEVEL_M))
    centres = np.array([s.mean(axis=0) for s in sections])
    last = len(sections) - 1
    tangents = np.array(
        [centres[max(i - 1, 0)] - centres[min(i + 1, last)] for i in range(len(sections))]
    )
    widths = section_widths_m(sections, tangents)
    return LEVEL_M * (levels + 0.5), _running_median(widths)


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


def _level_sets(
    points_m: NDArray[np.float64], distance: NDArray[np.float64]
) -> list[NDArray[np.float64]]:
    """The points (K, 3) of each :data:`LEVEL_M` level set of ``distance``, nearest first."""
    levels = np.floor(distance / LEVEL_M).astype(np.intp)
    order = np.argsort(levels, kind="stable")
    _, starts = np.unique(levels[order], return_index=True)
    return np.split(points_m[order], starts[1:])


@dataclass(frozen=True)
class LeafGraph:
    """A leaf's points linked for geodesic distances: ``means_m`` (V, 3) the means of its
    voxels (:func:`fieldapp.recon.organs.voxel_means`), ``inverse`` (M,) each point's voxel,
    ``links`` (V, V) sparse, the lengths of the links shorter than :data:`LINK_M`."""

    means_m: NDArray[np.float64]
    inverse: NDArray[np.intp]
    links: csr_matrix

    @classmethod
    def of(cls, points_m: NDArray[np.float64]) -> LeafGraph:
        """The graph of a leaf's points (M, 3)."""
        means, inverse = voxel_means(points_m)
        pairs = cKDTree(means).query_pairs(LINK_M, output_type="ndarray")
        length = np.linalg.norm(means[pairs[:, 0]] - means[pairs[:, 1]], axis=1)
        links = coo_matrix((length + 1e-9, (pairs[:, 0], pairs[:, 1])), shape=(len(means),) * 2)
        return cls(means, inverse, links.tocsr())

    def geodesic_m(self, sources: NDArray[np.intp]) -> NDArray[np.float64]:
        """(M,) every point's shortest distance from any of the points ``sources`` along the
        links; a voxel the links do not reach (a piece cut off by a gap) gets its nearest
        reached voxel's distance plus the straight gap."""
        starts = np.unique(self.inverse[sources])
        distance = dijkstra(self.links, directed=False, indices=starts, min_only=True)
        reached = np.isfinite(distance)
        if not reached.all():
            gap, nearest = cKDTree(self.means_m[reached]).query(self.means_m[~reached])
            distance[~reached] = distance[reached][nearest] + gap
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
    sections: list[NDArray[np.float64]], tangents: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(S,) flattened width of each cross-section's points (K_s, 3) seen along its tangent
    (S, 3): the span across it (between the 2nd and 98th percentiles, scaled to the whole
    span of evenly spread points: noise widens the extremes, not the quantiles) times the
    length per span of the parabola fitted to the section's profile (a folded blade measured
    flat); 0 for a section of fewer than 5 points. The 3 x 3 eigen and least-squares problems
    of a leaf's sections are solved together (each alone costs more in calls than in work)."""
    widths = np.zeros(len(sections))
    norms = np.linalg.norm(tangents, axis=1) if len(sections) else np.zeros(0)
    chosen = [i for i in range(len(sections)) if norms[i] >= 1e-9 and len(sections[i]) >= 5]
    if not chosen:
        return widths
    flat = []
    for i in chosen:
        t = tangents[i] / norms[i]
        q = sections[i] - sections[i].mean(axis=0)
        flat.append(q - np.outer(q @ t, t))
    _, vectors = np.linalg.eigh(np.stack([q.T @ q for q in flat]))
    spans, normal, rhs, ends = [], [], [], []
    for q, v in zip(flat, vectors, strict=True):
        across, height = q @ v[:, 2], q @ v[:, 1]
        ordered = np.sort(across)
        edge = round(EDGE_QUANTILE / 100.0 * (len(ordered) - 1))
        spans.append((ordered[-1 - edge] - ordered[edge]) / (1.0 - 2.0 * edge / (len(ordered) - 1)))
        design = np.stack([np.ones_like(across), across, across * across], axis=1)
        normal.append(design.T @ design + 1e-12 * np.eye(3))
        rhs.append(design.T @ height)
        ends.append((ordered[0], ordered[-1]))
    curve = np.linalg.solve(np.stack(normal), np.stack(rhs)[:, :, None])[:, :, 0]
    low, high = np.array(ends).T
    x = low[:, None] + (high - low)[:, None] * np.linspace(0.0, 1.0, 32)
    y = curve[:, :1] + curve[:, 1:2] * x + curve[:, 2:] * x * x
    chord = high - low
    arc = np.hypot(np.diff(x, axis=1), np.diff(y, axis=1)).sum(axis=1)
    stretch = np.divide(arc, chord, out=np.ones_like(arc), where=chord > 0)
    widths[chosen] = np.array(spans) * stretch
    return widths


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
