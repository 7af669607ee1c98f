"""Organs of one plant: its stem (and the rolled whorl on top of it) and one instance per
expanded leaf, from the plant's points alone (docs/RECONSTRUCTION.md, "Organs").

1. **Stem axis**: the stem traced up from its foot as a circle in each slice, the line through
   the circles' centres (refined on the stem-like points of a thin stem), at any lean up to
   31 degrees, where that trace is a long clean cylinder or leans; otherwise (a seedling's
   short stem) a line through the foot fitted to the stem-like points (:func:`fit_stem_axis`).
2. **Stem**: the points within a cylinder around the axis a little wider than the stem; the
   part of it above the highest leaf's insertion is the whorl.
3. **Leaves**: what is left are the leaves, each one a branch that leaves the stem: connected
   components (1 cm links) of the points outside the cylinder. A component that does not reach
   the stem is a piece of a leaf cut off by a gap in the data: it joins the leaf it lies
   nearest to. A component leaving the stem at two places is split between them, and one that
   forks going away from the stem is as many leaves as it has leaf-sized arms (two leaves
   lying over each other near the stem). Leaves are numbered from the bottom by where they
   leave the stem.

Works on any plant's points (N, 3), field frame, z up, whatever split the plot into plants.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from fieldapp.recon.traits import circumcentres

ORGAN_NONE, ORGAN_STEM, ORGAN_LEAF, ORGAN_WHORL = 0, 1, 2, 3
"""Per-point organ codes (``organ`` in the PLY files)."""

FOOT_SEARCH_M = 0.02
FOOT_HEIGHT_M = 0.03
"""The foot is the median of the points within this of the base, this high above the ground
(below the lowest leaf)."""

SLICE_M = 0.02
MAX_LEAN = 0.6
"""The stem's axis is traced up the plant in slices this thick, along a line leaning at most
this much (horizontal drift per metre of height: 31 degrees), through the plant's lower half
(:data:`AXIS_HEIGHT`)."""

AXIS_HEIGHT = 0.5

RING_RADII = (0.7, 1.35)
RING_BAND = (0.0025, 0.25)
RING_TRIALS = 256
"""In each slice the stem is the circle, of a radius within :data:`RING_RADII` of the foot's,
with the most points within its band (the larger of :data:`RING_BAND`'s metres and share of
the radius): the best of :data:`RING_TRIALS` circles through three of the slice's points."""

RING_MIN_SHARE = 0.35
RING_GATE = (0.5, 0.006)
RING_MISSES = 3
"""A slice's circle is the stem if it holds at least :data:`RING_MIN_SHARE` of the foot's
circle's points and lies within :data:`RING_GATE` (share of the radius plus metres) of where
the line traced so far puts the stem; :data:`RING_MISSES` slices in a row without it end the
trace."""

TRUST_SPAN_M = 0.10
TRUST_SLICES = 5
TRUST_OFF_M = 0.003
PREFER_SPAN_M = 0.16
PREFER_LEAN = 0.14
"""The trace is used when it is a clean cylinder (at least :data:`TRUST_SLICES` circles over
:data:`TRUST_SPAN_M` of height, their centres within :data:`TRUST_OFF_M` of the line, median)
and either that long (:data:`PREFER_SPAN_M`, a grown plant's stem) or leaning more than the
stem-like fit follows (:data:`PREFER_LEAN`, 8 degrees: its first band, 2 cm about the
vertical, holds such a stem for 14 cm only). Elsewhere the stem-like fit
(:func:`_fit_to_stem_like`) is used: on a seedling's short stem, hidden by its leaves in a
rendered plot, a trace is 4-14 cm long and was 3-6 degrees off where the stem-like fit was
within 1 (and up to 30 off where it is shorter than :data:`TRUST_SPAN_M`)."""

TILT_SEARCH_M = 0.06
TILT_HEIGHT = 0.5
FIRST_KEEP_M = (0.02, 0.012, 0.008)
MAX_TILT = 0.2
"""The stem-like fit: points within this of the foot, up to this share of the plant's height,
fitted within these bands of the line in turn (starting at 8 mm, a stem leaning 4-5 degrees
kept too few points and stayed vertical), its tilt capped at 11 degrees."""

TRIM_M = 0.0025
"""The line through the slices' centres is refitted without the centres farther from it than
this or 2.5 times their median distance (a leaf's sheath pulling a node's circle aside)."""

SHAPE_RADIUS_M = 0.012
MIN_LINEARITY = 0.6
COS_UPRIGHT = 0.9
LINE_KEEP_M = (0.012, 0.008)
MIN_REFINE_POINTS = 40
"""A thin stem (a seedling's, 5-7 mm) has few points in a slice; its axis is refined on the
stem-like points (their neighbourhood within :data:`SHAPE_RADIUS_M` an upright column:
linearity above :data:`MIN_LINEARITY`, long axis within :data:`COS_UPRIGHT` of the vertical)
within :data:`LINE_KEEP_M` of the line, while at least :data:`MIN_REFINE_POINTS` are. On a
thicker stem (8-12 mm, grown plants) few points are stem-like: a 2.4 cm neighbourhood of it is
no column, and the first fit of the axis, to those points alone, came out 2.5 degrees off
upright stems on average and 6-12 degrees off stems leaning 15-25 degrees."""

CUT_MARGIN_M = 0.016
"""The stem's cylinder: its radius plus this margin (noise, the leaf sheath, the error of the
axis' tilt: chosen on three seeds, 47 of 48 plants with the right leaf count, against 28 with
8 mm and 43 with 2 cm)."""

MIN_CUT_RADIUS_M = 0.014

LINK_M = 0.012
GRAPH_VOXEL_M = 0.004
"""Points closer than :data:`LINK_M` are joined in a leaf (the means of :data:`GRAPH_VOXEL_M`
voxels, to keep the graphs small)."""

MIN_LEAF_POINTS = 40
MIN_LEAF_EXTENT_M = 0.04
"""A branch shorter than this, or with fewer points, is not an expanded leaf."""

TOUCH_M = 0.012
"""A component reaching within this of the cylinder leaves the stem (is a leaf's base)."""

BASE_LINK_M = 0.015
MIN_BASE_POINTS = 15
"""A branch's base points (within :data:`TOUCH_M` of the cylinder) linked within
:data:`BASE_LINK_M`; two groups of :data:`MIN_BASE_POINTS` or more are two leaves."""

SHELL_GAP_M = 0.005
SHELL_LINK_M = 0.006
SHELL_REACH_M = 0.06
"""Leaves grow back into the stem's cylinder down to the stem's radius plus
:data:`SHELL_GAP_M`, along links of :data:`SHELL_LINK_M`, at most :data:`SHELL_REACH_M` along
them."""

FORK_LEVEL_M = 0.01
"""A branch's level sets: its points by their distance from the stem along the branch, in
steps of this."""

FRAGMENT_JOIN_M = 0.06
"""A fragment joins the nearest leaf within this distance; farther, it stays unassigned."""


@dataclass(frozen=True)
class StemAxis:
    """The stem's axis: ``foot_m`` (3,) on the local ground, ``direction`` (3,) unit, upward."""

    foot_m: NDArray[np.float64]
    direction: NDArray[np.float64]

    def split(
        self, points_m: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(N,) height along the axis above the foot and (N,) distance from the axis."""
        offset = points_m - self.foot_m
        along = offset @ self.direction
        radial = np.linalg.norm(offset - along[:, None] * self.direction, axis=1)
        return along, radial


@dataclass(frozen=True)
class Organs:
    """One plant's points split into organs.

    - ``organ``: (N,) uint8, one of the ``ORGAN_*`` codes;
    - ``leaf_id``: (N,) uint8, the leaf (1 = lowest) of each leaf point, 0 elsewhere;
    - ``axis``: the stem's axis; ``stem_radius_m``: first estimate of the stem's radius (its
      foot's points' median distance from the axis); ``cut_radius_m``: the stem cylinder's;
    - ``leaves``: per leaf, from the bottom, the indices of its points.
    """

    organ: NDArray[np.uint8]
    leaf_id: NDArray[np.uint8]
    axis: StemAxis
    stem_radius_m: float
    cut_radius_m: float
    leaves: list[NDArray[np.intp]]


def fit_stem_axis(
    points_m: NDArray[np.float64], foot_m: NDArray[np.float64], trace: bool = True
) -> StemAxis:
    """The stem's axis from the plant's points (N, 3) and a first guess of the stem's foot (3,)
    (base xy, local ground z). The stem is traced up from its foot as a circle in each slice
    (:func:`_ring`; the foot's radius from the points of its lowest centimetres, below any
    leaf), each slice searched where the line through the circles below puts it; the axis is
    the line through the circles' centres (:data:`TRIM_M`), refined on the stem-like points
    of a thin stem (:data:`MIN_REFINE_POINTS`). Any lean up to :data:`MAX_LEAN`: the trace
    does not assume the stem upright. Where the trace is not to be trusted
    (:data:`TRUST_SPAN_M`, :data:`PREFER_SPAN_M`) or ``trace=False`` (the plants step's
    ribbons, tuned with it: RECONSTRUCTION.md, "Organs"), the stem-like fit
    (:func:`_fit_to_stem_like`)."""
    guess = StemAxis(foot_m, np.array([0.0, 0.0, 1.0]))
    along, radial = guess.split(points_m)
    low = (radial < FOOT_SEARCH_M) & (along > 0.005) & (along < FOOT_HEIGHT_M)
    foot = foot_m.copy()
    if low.sum() >= 5:
        foot[:2] = np.median(points_m[low, :2], axis=0)
    height = float(points_m[:, 2].max() - foot[2])
    top = AXIS_HEIGHT * height
    traced = _trace_rings(points_m, foot, top) if trace else None
    if traced is None:
        tilt = _fit_to_stem_like(points_m, foot, height)
    else:
        foot[:2], tilt = traced
        tilt = _refine_on_stem_like(points_m, foot, tilt, top)
    direction = np.array([tilt[0], tilt[1], 1.0])
    return StemAxis(foot, direction / np.linalg.norm(direction))


def _fit_to_stem_like(
    points_m: NDArray[np.float64], foot: NDArray[np.float64], height: float
) -> NDArray[np.float64]:
    """Where no clean cylinder was traced: the tilt of the line through the foot fitted to the
    stem-like points within :data:`TILT_SEARCH_M` of the foot, up to :data:`TILT_HEIGHT` of
    the plant, within the first of :data:`FIRST_KEEP_M` of the vertical, then refitted on
    those within the next ones of the line (capped at :data:`MAX_TILT`)."""
    near = points_m[np.linalg.norm(points_m[:, :2] - foot[:2], axis=1) < TILT_SEARCH_M]
    near = near[(near[:, 2] > foot[2] + 0.005) & (near[:, 2] < foot[2] + TILT_HEIGHT * height)]
    return _refit_through_foot(
        near[_stem_like(near)], foot, np.zeros(2), FIRST_KEEP_M, 10, MAX_TILT
    )


def _refit_through_foot(
    stem_like: NDArray[np.float64],
    foot: NDArray[np.float64],
    tilt: NDArray[np.float64],
    bands_m: tuple[float, ...],
    min_points: int,
    cap: float | None = None,
) -> NDArray[np.float64]:
    """``tilt`` (2,) of the line through ``foot`` refitted (least squares) on the points
    ``stem_like`` (N, 3) within each of ``bands_m`` of the line in turn, while at least
    ``min_points`` are; each component clipped to ``cap`` when given."""
    dz = stem_like[:, 2] - foot[2]
    for band_m in bands_m:
        residual = np.linalg.norm(stem_like[:, :2] - foot[:2] - dz[:, None] * tilt, axis=1)
        keep = residual < band_m
        if keep.sum() < min_points:
            break
        tilt = (dz[keep] @ (stem_like[keep, :2] - foot[:2])) / float(dz[keep] @ dz[keep])
        if cap is not None:
            tilt = np.clip(tilt, -cap, cap)
    return tilt


def _trace_rings(
    points_m: NDArray[np.float64], foot: NDArray[np.float64], top: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The stem traced in slices up to ``top`` above ``foot`` (3,): the traced line's plan
    position at the foot's height (2,) and its tilt (2,), or None unless the trace is a clean
    cylinder (:data:`TRUST_SPAN_M`, :data:`PREFER_SPAN_M`)."""
    dz = points_m[:, 2] - foot[2]
    lower = (dz > 0.005) & (dz < top)
    xy, dz = points_m[lower, :2], dz[lower]
    rng = np.random.default_rng(0)  # the same points, the same axis
    origin, tilt = foot[:2].copy(), np.zeros(2)
    radius = count = None
    heights: list[float] = []
    centres: list[NDArray[np.float64]] = []
    weights: list[int] = []
    misses = 0
    for bottom in np.arange(0.005, top, SLICE_M):
        middle = bottom + SLICE_M / 2
        predicted = origin + middle * tilt
        slack = MAX_LEAN * (middle - heights[-1]) if 0 < len(heights) < 3 else 0.0
        reach = (2.0 * FOOT_SEARCH_M if radius is None else 1.6 * radius + 0.012) + slack
        inside = (dz >= bottom) & (dz < bottom + SLICE_M)
        chosen = xy[inside]
        chosen = chosen[np.linalg.norm(chosen - predicted, axis=1) < reach]
        if radius is None and len(chosen) >= 8:
            spread = np.linalg.norm(chosen - chosen.mean(axis=0), axis=1)
            radius = float(np.clip(np.median(spread), 0.003, 0.02))
        found = _ring(chosen, radius, rng) if radius is not None and len(chosen) >= 8 else None
        if found is not None and radius is not None:
            centre, support = found
            count = count or support
            gate = RING_GATE[0] * radius + RING_GATE[1] + slack if heights else reach
            if support < RING_MIN_SHARE * count or np.linalg.norm(centre - predicted) > gate:
                found = None
        if found is None:
            misses += 1
            if misses >= RING_MISSES:
                break
            continue
        misses = 0
        heights.append(middle)
        centres.append(centre)
        weights.append(support)
        if len(heights) == 1:
            origin = centre - middle * tilt
        else:
            origin, tilt = _line_through(np.array(heights), np.array(centres), np.array(weights))
    if len(heights) < 3:
        return None
    z, c, w = np.array(heights), np.array(centres), np.array(weights, dtype=np.float64)
    use = np.ones(len(z), dtype=bool)
    for _ in range(3):
        origin, tilt = _line_through(z[use], c[use], w[use])
        off = np.linalg.norm(c - origin - z[:, None] * tilt, axis=1)
        keep = off < max(TRIM_M, 2.5 * float(np.median(off)))
        if keep.sum() < 3 or (keep == use).all():
            break
        use = keep
    off = np.linalg.norm(c - origin - z[:, None] * tilt, axis=1)
    span = float(z[use].max() - z[use].min())
    clean = use.sum() >= TRUST_SLICES and np.median(off[use]) <= TRUST_OFF_M
    better = span >= PREFER_SPAN_M or np.linalg.norm(tilt) >= PREFER_LEAN
    return (origin, tilt) if clean and span >= TRUST_SPAN_M and better else None


def _line_through(
    z: NDArray[np.float64], centres: NDArray[np.float64], weights: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The weighted least-squares line through ``centres`` (K, 2) at heights ``z`` (K,) above
    the foot: its plan position at height 0 (2,) and its tilt (2,), capped at
    :data:`MAX_LEAN`."""
    root = np.sqrt(weights)[:, None]
    design = np.stack([np.ones_like(z), z], axis=1) * root
    origin, tilt = np.linalg.lstsq(design, centres * root, rcond=None)[0]
    lean = float(np.linalg.norm(tilt))
    if lean > MAX_LEAN:
        tilt = tilt * (MAX_LEAN / lean)
    return origin, tilt


def _ring(
    xy: NDArray[np.float64], radius: float, rng: np.random.Generator
) -> tuple[NDArray[np.float64], int] | None:
    """Centre (2,) and support of the best circle through ``xy`` (N, 2) of a radius near
    ``radius`` (:data:`RING_RADII`), or None."""
    a, b, c = (xy[k] for k in rng.integers(0, len(xy), (3, RING_TRIALS)))
    centres, valid = circumcentres(a, b, c, 1e-12)
    radii = np.linalg.norm(a - centres, axis=1)
    valid &= (radii > RING_RADII[0] * radius) & (radii < RING_RADII[1] * radius)
    if not valid.any():
        return None
    centres, radii = centres[valid], radii[valid]
    band = max(RING_BAND[0], RING_BAND[1] * radius)
    distance = np.linalg.norm(xy[None, :, :] - centres[:, None, :], axis=2)
    support = (np.abs(distance - radii[:, None]) < band).sum(axis=1)
    best = int(np.argmax(support))
    return centres[best], int(support[best])


def _refine_on_stem_like(
    points_m: NDArray[np.float64], foot: NDArray[np.float64], tilt: NDArray[np.float64], top: float
) -> NDArray[np.float64]:
    """``tilt`` refitted, through the foot, on the stem-like points near the line
    (:data:`MIN_REFINE_POINTS`)."""
    dz = points_m[:, 2] - foot[2]
    off = np.linalg.norm(points_m[:, :2] - foot[:2] - dz[:, None] * tilt, axis=1)
    near = points_m[(off < 0.03) & (dz > 0.005) & (dz < top)]
    return _refit_through_foot(near[_stem_like(near)], foot, tilt, LINE_KEEP_M, MIN_REFINE_POINTS)


def _stem_like(points_m: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(N,) True where the neighbourhood (within :data:`SHAPE_RADIUS_M`) is a thin upright
    column: much longer than wide (linearity), its long direction near the vertical. A leaf's
    neighbourhood is a sheet."""
    n = len(points_m)
    if n < 6:
        return np.zeros(n, dtype=bool)
    pairs = cKDTree(points_m).query_pairs(SHAPE_RADIUS_M, output_type="ndarray")
    itself = np.arange(n)
    both_ways = np.stack(
        [np.r_[pairs[:, 0], pairs[:, 1], itself], np.r_[pairs[:, 1], pairs[:, 0], itself]], 1
    )
    neighbours = pair_graph(both_ways, n)
    count = np.bincount(both_ways[:, 0], minlength=n).astype(np.float64)
    x, y, z = points_m.T
    sums = neighbours @ np.stack([x, y, z, x * x, y * y, z * z, x * y, x * z, y * z], axis=1)
    sums /= count[:, None]
    mean = sums[:, :3]
    second = sums[:, [3, 6, 7, 6, 4, 8, 7, 8, 5]].reshape(n, 3, 3)
    covariance = second - mean[:, :, None] * mean[:, None, :]
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    l2, l1 = eigenvalues[:, 1], eigenvalues[:, 2]
    linearity = (l1 - l2) / np.maximum(l1, 1e-12)
    upright = np.abs(eigenvectors[:, 2, 2]) > COS_UPRIGHT
    return (count >= 6) & (linearity > MIN_LINEARITY) & upright  # type: ignore[no-any-return]


def segment_organs(
    points_m: NDArray[np.float64], foot_m: NDArray[np.float64], split_forks: bool = True
) -> Organs:
    """Split a plant's points (N, 3) into stem, whorl and leaves, given a first guess of the
    stem's foot (3,) (base xy, local ground z). ``split_forks``: a branch forking into
    leaf-sized arms is one leaf per arm (two leaves lying over each other near the stem);
    without it such a branch is one leaf, as the plants step's ribbons trace it."""
    return Branches.of(points_m, foot_m).organs(split_forks)


@dataclass(frozen=True)
class Branches:
    """A plant's stem axis and the branches leaving its stem, before any fork is split: what
    :func:`segment_organs` computes with and without ``split_forks`` alike, so that a caller
    needing both (the plants step's ribbons) finds the axis and the graph once."""

    points_m: NDArray[np.float64]
    axis: StemAxis
    along: NDArray[np.float64]
    radial: NDArray[np.float64]
    stem_radius_m: float
    cut_m: float
    graph: _LeafGraph
    point_voxel: NDArray[np.intp]
    branches: list[NDArray[np.intp]]
    pieces: list[NDArray[np.intp]]

    @staticmethod
    def of(
        points_m: NDArray[np.float64], foot_m: NDArray[np.float64], trace: bool = True
    ) -> Branches:
        """The plant's points (N, 3) and a first guess of its stem's foot (3,); ``trace``: as
        :func:`fit_stem_axis`'s."""
        axis = fit_stem_axis(points_m, foot_m, trace)
        along, radial = axis.split(points_m)
        foot_ring = (along > 0.005) & (along < FOOT_HEIGHT_M) & (radial < FOOT_SEARCH_M)
        stem_radius = float(np.median(radial[foot_ring])) if foot_ring.sum() >= 5 else 0.006
        stem_radius = float(np.clip(stem_radius, 0.003, 0.012))
        cut = max(stem_radius + CUT_MARGIN_M, MIN_CUT_RADIUS_M)
        outside = np.flatnonzero(radial > cut)
        graph = _LeafGraph.of(points_m[outside])
        point_voxel = np.full(len(points_m), -1, dtype=np.intp)
        point_voxel[outside] = graph.voxel
        branches, pieces = _branches(points_m, outside, graph, point_voxel, radial, cut)
        return Branches(
            points_m, axis, along, radial, stem_radius, cut, graph, point_voxel, branches, pieces
        )

    def organs(self, split_forks: bool = True) -> Organs:
        """The organs, each branch one leaf or (``split_forks``) one leaf per arm."""
        points_m, along, radial, cut = self.points_m, self.along, self.radial, self.cut_m
        leaves = self.branches
        if leaves and split_forks:
            leaves = _split_forks(leaves, self.graph, self.point_voxel, radial, cut)
        leaves = _join_pieces(points_m, leaves, self.pieces)
        leaves = _grow_into_shell(
            points_m, leaves, along, radial, self.stem_radius_m + SHELL_GAP_M, cut
        )
        starts = [float(along[leaf][np.argmin(radial[leaf])]) for leaf in leaves]
        leaves = [leaves[i] for i in np.argsort(starts, kind="stable")]
        organ = np.where(radial <= cut, ORGAN_STEM, ORGAN_NONE).astype(np.uint8)
        leaf_id = np.zeros(len(points_m), dtype=np.uint8)
        for number, leaf in enumerate(leaves, start=1):
            organ[leaf] = ORGAN_LEAF
            leaf_id[leaf] = min(number, 255)
        if leaves:
            top_insertion = max(starts)
            organ[(organ == ORGAN_STEM) & (along > top_insertion)] = ORGAN_WHORL
        return Organs(organ, leaf_id, self.axis, self.stem_radius_m, cut, leaves)


def _grow_into_shell(
    points_m: NDArray[np.float64],
    leaves: list[NDArray[np.intp]],
    along: NDArray[np.float64],
    radial: NDArray[np.float64],
    inner_m: float,
    cut_m: float,
) -> list[NDArray[np.intp]]:
    """Leaves grown back into the stem's cylinder down to ``inner_m`` from the axis: each point
    of that shell joins the leaf it is nearest to along :data:`SHELL_LINK_M` links (within
    :data:`SHELL_REACH_M`), if it lies no higher up the stem (``along``) than the middle (median
    height) of where that leaf crosses the cylinder's surface (its points within
    :data:`TOUCH_M` outside it). A leaf standing up beside the whorl runs for centimetres inside
    the cylinder before it leaves it; it leaves the stem upwards, so its part inside lies below
    its crossing. Above it, the shell's points are the stem's surface, a sheath or the base of
    the leaf above, reached along the stem: on the touching plots they pulled the collar up
    (docs/TRAITS.md, "Leaves lying over each other")."""
    if not leaves:
        return leaves
    shell = np.flatnonzero((radial > inner_m) & (radial <= cut_m))
    bases = [leaf[radial[leaf] <= cut_m + SHELL_REACH_M] for leaf in leaves]
    region = np.concatenate([*bases, shell])
    owner = np.concatenate(
        [np.full(len(b), k) for k, b in enumerate(bases)] + [np.full(len(shell), -1)]
    )
    if len(shell) == 0 or len(region) == len(shell):
        return leaves
    region_points = points_m[region]
    pairs = cKDTree(region_points).query_pairs(SHELL_LINK_M, output_type="ndarray")
    graph = pair_graph(pairs, len(region), pair_lengths(region_points, pairs) + 1e-9)
    starts = np.flatnonzero(owner >= 0)
    distance, _, source = dijkstra(
        graph, directed=False, indices=starts, min_only=True, return_predecessors=True
    )
    grown = list(leaves)
    in_shell = np.arange(len(region)) >= len(region) - len(shell)
    reached = in_shell & (distance <= SHELL_REACH_M)
    nearest = owner[np.maximum(source, 0)]
    for k, leaf in enumerate(leaves):
        crossing = leaf[radial[leaf] <= cut_m + TOUCH_M]
        if len(crossing) == 0:
            continue
        joined = region[reached & (nearest == k)]
        joined = joined[along[joined] <= np.median(along[crossing])]
        grown[k] = np.unique(np.concatenate([leaf, joined]))
    return grown


def voxel_means(
    points_m: NDArray[np.float64],
    voxel_m: float = GRAPH_VOXEL_M,
    groups: NDArray[np.intp] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """The mean point (V, 3) of every occupied ``voxel_m`` voxel and each point's voxel (N,):
    the graphs are built on these, a few per square centimetre of leaf. With ``groups`` (N,)
    (non-negative) each group's points have voxels of their own, the groups' one after the
    other: a group's voxels and means are those of its points alone."""
    cells = np.floor(points_m / voxel_m).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    if groups is not None:
        keys += groups.astype(np.int64) * int(np.prod(span))
    _, inverse = np.unique(keys, return_inverse=True)
    count = np.bincount(inverse).astype(np.float64)
    means = np.stack([np.bincount(inverse, points_m[:, i]) for i in range(3)], 1) / count[:, None]
    return means, inverse.astype(np.intp)


def pair_graph(
    pairs: NDArray[np.intp], size: int, weights: NDArray[np.float64] | None = None
) -> csr_matrix:
    """(size, size) sparse graph of the links ``pairs`` (P, 2) (each pair once, as
    ``cKDTree.query_pairs`` gives them) weighted by ``weights`` (P,) (default 1). Its rows'
    columns are left in the pairs' order: the graph searches do not need them sorted, and
    sorting them cost more than the searches."""
    data = np.ones(len(pairs)) if weights is None else weights
    links = coo_matrix((data, (pairs[:, 0], pairs[:, 1])), shape=(size, size))
    links.has_canonical_format = True  # no pair twice: nothing to sum
    return links.tocsr()


def pair_lengths(points_m: NDArray[np.float64], pairs: NDArray[np.intp]) -> NDArray[np.float64]:
    """(P,) the distance between the points (N, 3) of each pair (P, 2)."""
    step = points_m[pairs[:, 0]] - points_m[pairs[:, 1]]
    return np.sqrt(np.einsum("ij,ij->i", step, step))  # type: ignore[no-any-return]


@dataclass(frozen=True)
class _LeafGraph:
    """The points outside the stem's cylinder as a graph: ``means`` (V, 3) of their
    :data:`GRAPH_VOXEL_M` voxels, each point's voxel ``voxel`` (N,), the links between voxels
    closer than :data:`LINK_M` weighted by their lengths (``graph``, each link once) and each
    voxel's connected component ``component`` (V,)."""

    means: NDArray[np.float64]
    voxel: NDArray[np.intp]
    pairs: NDArray[np.intp]
    lengths: NDArray[np.float64]
    graph: csr_matrix
    component: NDArray[np.intp]

    @staticmethod
    def of(points_m: NDArray[np.float64]) -> _LeafGraph:
        if len(points_m) == 0:
            empty = np.zeros(0, dtype=np.intp)
            no_pairs = np.zeros((0, 2), dtype=np.intp)
            return _LeafGraph(
                np.zeros((0, 3)), empty, no_pairs, np.zeros(0), csr_matrix((0, 0)), empty
            )
        means, inverse = voxel_means(points_m)
        pairs = cKDTree(means).query_pairs(LINK_M, output_type="ndarray")
        lengths = pair_lengths(means, pairs) + 1e-9
        graph = pair_graph(pairs, len(means), lengths)
        component = connected_components(graph, directed=False)[1].astype(np.intp)
        return _LeafGraph(means, inverse, pairs, lengths, graph, component)

    def part(
        self, voxel: NDArray[np.intp]
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], csr_matrix]:
        """The voxels (U,) (sorted) of the points whose voxels are ``voxel`` (M,), each
        point's place among them (M,) and the graph between them (U, U)."""
        used, local = np.unique(voxel, return_inverse=True)
        return used, local.astype(np.intp), self.graph[used][:, used]


def _split_at_bases(
    points_m: NDArray[np.float64],
    members: NDArray[np.intp],
    graph: _LeafGraph,
    point_voxel: NDArray[np.intp],
    radial: NDArray[np.float64],
    cut_m: float,
) -> list[NDArray[np.intp]]:
    """One branch per base: a branch leaving the stem at two places (two leaves touching
    further out) is split, each point going to the base it is nearest to along the branch."""
    at_base = radial[members] < cut_m + TOUCH_M
    base = members[at_base]
    groups = _components_linked(points_m[base], BASE_LINK_M)
    sizes = np.bincount(groups)
    kept = np.flatnonzero(sizes >= MIN_BASE_POINTS)
    if len(kept) < 2:
        return [members]
    _, inverse, links = graph.part(point_voxel[members])
    distances = []
    for group in kept:
        starts = np.unique(inverse[at_base][groups == group])
        distances.append(dijkstra(links, directed=False, indices=starts, min_only=True))
    owner = np.argmin(np.stack(distances), axis=0)[inverse]
    return [members[owner == k] for k in range(len(kept)) if np.any(owner == k)]


def _split_forks(
    leaves: list[NDArray[np.intp]],
    graph: _LeafGraph,
    point_voxel: NDArray[np.intp],
    radial: NDArray[np.float64],
    cut_m: float,
) -> list[NDArray[np.intp]]:
    """Every branch (``leaves``, disjoint in voxels) that forks into two or more long arms
    going away from the stem is as many leaves lying over each other near the stem: one leaf
    per arm (:func:`_arm_ends`), each voxel of the shared part going to the arm whose
    shortest paths to the stem run through it most (:func:`_arms_behind`), what is left to
    the arm nearest along the branch. All of a plant's branches at once: one graph, one
    search from the stem."""
    voxels = len(graph.means)
    branch = np.full(voxels, -1, dtype=np.intp)
    for k, leaf in enumerate(leaves):
        branch[point_voxel[leaf]] = k
    pairs, lengths = graph.pairs, graph.lengths
    inside = (branch[pairs[:, 0]] == branch[pairs[:, 1]]) & (branch[pairs[:, 0]] >= 0)
    pairs = pairs[inside]
    links = pair_graph(pairs, voxels, lengths[inside])
    near = np.zeros(voxels, dtype=bool)
    at_stem = np.flatnonzero(radial < cut_m + TOUCH_M)
    near[point_voxel[at_stem][point_voxel[at_stem] >= 0]] = True
    near &= branch >= 0
    if not near.any():
        return leaves
    distance, towards_stem, _ = dijkstra(
        links, directed=False, indices=np.flatnonzero(near), min_only=True, return_predecessors=True
    )
    reached = np.isfinite(distance)
    level = np.where(reached, np.floor(np.where(reached, distance, 0.0) / FORK_LEVEL_M), -2)
    level = level.astype(np.intp)
    lo, hi = level[pairs[:, 0]], level[pairs[:, 1]]
    piece = connected_components(pair_graph(pairs[lo == hi], voxels), directed=False)[1]
    pieces = int(piece.max()) + 1
    piece_level = np.zeros(pieces, dtype=np.intp)
    piece_level[piece] = level
    count = np.bincount(graph.voxel, minlength=voxels)
    piece_points = np.bincount(piece, weights=count, minlength=pieces).astype(np.float64)
    step = pairs[(np.abs(lo - hi) == 1) & (np.minimum(lo, hi) >= 0)]
    outward = level[step[:, 0]] < level[step[:, 1]]
    inner = np.where(outward, step[:, 0], step[:, 1])
    outer = np.where(outward, step[:, 1], step[:, 0])
    steps = np.unique(piece[inner].astype(np.int64) * pieces + piece[outer])
    if np.bincount(steps // pieces, minlength=pieces).max(initial=0) < 2:
        return leaves  # no level set splits: no branch forks
    ends = _arm_ends(steps, pieces, piece_level, piece_points)
    if not ends:
        return leaves
    seeds = np.full(pieces, -1, dtype=np.intp)
    for k, end in enumerate(ends):
        seeds[end] = k
    arm = seeds[piece]
    forked = np.zeros(len(leaves), dtype=bool)
    forked[branch[arm >= 0]] = True
    shared = (arm < 0) & forked[np.maximum(branch, 0)] & (branch >= 0)
    behind = _arms_behind(towards_stem, arm, count, len(ends))
    through = shared & (behind.max(axis=1) > 0)
    arm[through] = np.argmax(behind[through], axis=1)
    _, _, source = dijkstra(
        links,
        directed=False,
        indices=np.flatnonzero(arm >= 0),
        min_only=True,
        return_predecessors=True,
    )
    rest = shared & (arm < 0) & (source >= 0)
    arm[rest] = arm[source[rest]]
    out: list[NDArray[np.intp]] = []
    for k, leaf in enumerate(leaves):
        if not forked[k]:
            out.append(leaf)
            continue
        of_leaf = arm[point_voxel[leaf]]
        arms = np.unique(of_leaf[of_leaf >= 0])
        of_leaf = np.where(of_leaf >= 0, of_leaf, arms[0])
        out += [leaf[of_leaf == a] for a in arms]
    return out


def _arm_ends(
    steps: NDArray[np.int64],
    pieces: int,
    piece_level: NDArray[np.intp],
    piece_points: NDArray[np.float64],
) -> list[list[int]]:
    """The arms of a branch's level-set pieces (``pieces`` of them, each at a level with so
    many points; ``steps`` the links inner * pieces + outer between pieces of consecutive
    levels): the pieces beyond every fork, a fork being a piece from which two or more parts
    of a leaf's size (:data:`MIN_LEAF_POINTS`, :data:`MIN_LEAF_EXTENT_M` beyond it) go
    outwards without meeting again. Found by joining the pieces from the outermost level
    inwards (the join tree of the distance from the stem); an arm with a fork further out is
    not one, the arms beyond that fork are."""
    children: dict[int, list[int]] = {}
    for key in steps.tolist():
        children.setdefault(key // pieces, []).append(key % pieces)
    level = piece_level.tolist()
    parent = list(range(pieces))
    size = piece_points.tolist()
    top = list(level)
    forked = [False] * pieces
    done: list[int] = []
    reach = MIN_LEAF_EXTENT_M / FORK_LEVEL_M - 1e-9

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    ends: list[list[int]] = []
    for p in np.argsort(-piece_level, kind="stable").tolist():
        roots = {find(c) for c in children.get(p, ())}
        arms = [r for r in roots if size[r] >= MIN_LEAF_POINTS and top[r] - level[p] >= reach]
        if len(arms) >= 2:
            owner = [find(q) for q in done]
            ends += [
                [q for q, o in zip(done, owner, strict=True) if o == r]
                for r in arms
                if not forked[r]
            ]
        for r in roots:
            parent[r] = p
            size[p] += size[r]
            top[p] = max(top[p], top[r])
            forked[p] = forked[p] or forked[r]
        forked[p] = forked[p] or len(arms) >= 2
        done.append(p)
    return ends


def _arms_behind(
    parent: NDArray[np.intp], arm: NDArray[np.intp], count: NDArray[np.intp], arms: int
) -> NDArray[np.float64]:
    """(V, arms): for every voxel of a shortest-path tree from the stem (``parent``: each
    voxel's next one towards the stem, negative at the stem), the points of each arm (``arm``
    per voxel, -1 for none; ``count`` points per voxel) whose paths to the stem pass through
    it."""
    up = np.where(parent >= 0, parent, -1)
    depth = (up >= 0).astype(np.intp)
    jump = up.copy()
    while np.any(jump >= 0):  # hops to the stem by pointer jumping
        going = np.flatnonzero(jump >= 0)
        depth[going], jump[going] = depth[going] + depth[jump[going]], jump[jump[going]]
    total = np.zeros((len(parent), arms))
    own = np.flatnonzero(arm >= 0)
    total[own, arm[own]] = count[own]
    by_depth = np.argsort(-depth, kind="stable")
    bounds = np.flatnonzero(np.diff(depth[by_depth])) + 1
    for group in np.split(by_depth, bounds):
        group = group[up[group] >= 0]
        np.add.at(total, up[group], total[group])
    return total


def _components_linked(points_m: NDArray[np.float64], link_m: float) -> NDArray[np.intp]:
    """(N,) component of every point, points closer than ``link_m`` linked."""
    pairs = cKDTree(points_m).query_pairs(link_m, output_type="ndarray")
    graph = pair_graph(pairs, len(points_m))
    return connected_components(graph, directed=False)[1].astype(np.intp)  # type: ignore[no-any-return]


def _branches(
    points_m: NDArray[np.float64],
    outside: NDArray[np.intp],
    graph: _LeafGraph,
    point_voxel: NDArray[np.intp],
    radial: NDArray[np.float64],
    cut_m: float,
) -> tuple[list[NDArray[np.intp]], list[NDArray[np.intp]]]:
    """The branches (indices into ``points_m``): the components of the points ``outside`` the
    cylinder (their ``graph``; ``point_voxel``: each point's voxel in it, -1 inside) that reach
    the stem and are large enough, split where they leave the stem at two places; and the
    other large pieces, which join the nearest leaf (:func:`_join_pieces`)."""
    labels = graph.component[graph.voxel]
    branches: list[NDArray[np.intp]] = []
    pieces: list[NDArray[np.intp]] = []
    for label in np.unique(labels):
        members = outside[labels == label]
        if len(members) < MIN_LEAF_POINTS // 4:
            continue
        extent = float(np.ptp(points_m[members], axis=0).max())
        reaches = float(radial[members].min()) < cut_m + TOUCH_M
        if reaches and len(members) >= MIN_LEAF_POINTS and extent >= MIN_LEAF_EXTENT_M:
            branches += _split_at_bases(points_m, members, graph, point_voxel, radial, cut_m)
        else:
            pieces.append(members)
    return branches, pieces


def _join_pieces(
    points_m: NDArray[np.float64], leaves: list[NDArray[np.intp]], pieces: list[NDArray[np.intp]]
) -> list[NDArray[np.intp]]:
    """``leaves`` with each of the ``pieces`` (a leaf cut off by a gap) joined to the leaf it
    lies nearest to, within :data:`FRAGMENT_JOIN_M` (a new list; the arrays are not changed)."""
    leaves = list(leaves)
    if not leaves or not pieces:
        return leaves
    leaf_of = np.repeat(np.arange(len(leaves)), [len(leaf) for leaf in leaves])
    gap, nearest = cKDTree(points_m[np.concatenate(leaves)]).query(points_m[np.concatenate(pieces)])
    starts = np.cumsum([0] + [len(piece) for piece in pieces[:-1]])
    closest = starts + np.array([np.argmin(g) for g in np.split(gap, starts[1:])])
    for piece, at in zip(pieces, closest, strict=True):
        if gap[at] <= FRAGMENT_JOIN_M:
            leaf = leaf_of[nearest[at]]
            leaves[leaf] = np.concatenate([leaves[leaf], piece])
    return leaves
