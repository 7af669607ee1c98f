"""Leaves followed across contacts: the leaves of a plant whose canopy touches a neighbour's
are traced from their base as ribbons and continued where the neighbour took their outer part.

The geodesic assignment (:mod:`fieldapp.recon.geodesic`) gives a point to the stem it is
nearest to along the plant. Where a leaf's outer part lies *on* a neighbour's leaf with the
same slope (two sheets touching tangentially, within the sensor's noise) the neighbour reaches
that part sooner, and no local cost sees the contact: the normals agree across it. What differs
is the leaf itself: a ribbon (a smooth midrib whose direction and curvature continue, a width
that tapers) that runs on through the contact while the neighbour's leaf runs off at an angle.

For each plant with ambiguous points every leaf
(:class:`fieldapp.recon.organs.Branches`, unsplit) is traced (:func:`trace_leaf`): its midrib, the
centres of the 1 cm level sets of the geodesic distance from its base, and the width of each
section, up to where the leaf meets another plant (its sections touch another plant's points or
are ambiguous) or its width jumps (the neighbour holds one side of it, or another leaf joins).
Where another leaf lying over it joins it (the organ step keeps the two one branch), the
trace would end there, short of any contact, and a branch of leaves joined near the stem is
too wide to trace at all: such a branch is split at its forks and each arm traced on its own
(:func:`_arms_of`), an arm followed only when traced :data:`MIN_ARM_M`.
From there the ribbon is continued in 1 cm steps (:func:`follow`) along the parabola fitted (in
arc length) to the last :data:`FIT_M` of its midrib, its width following the taper fitted there;
each step takes the points inside it (across the ribbon within its half width, off its plane
within :data:`PLANE_TOLERANCE_M`) and is re-centred on them, so a leaf is followed as far as it
runs on, and past its width the leaf's surface out to its edges (:func:`_edges`: a blade is
channelled, and wider than the taper fitted near its base). A leaf that really ends there
(narrow, tapering) finds next to nothing. A neighbour's point that a continued ribbon runs
through changes hands, unless it lies on one of the neighbour's own leaves where that leaf is
held (traced, more than :data:`FIT_M` before its trace's end: a trace ends a little past where
the contact begins when the contact builds up gradually, a leaf tip lying on it) and is not
ambiguous; a point two ribbons run through goes to the one that reached it nearer to where its
leaf was seen whole. The points the steps missed among those they took go with them
(:func:`_with_strays`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from fieldapp.recon.leaf_traits import LeafGraph, section_widths_m
from fieldapp.recon.organs import Branches

LEVEL_M = 0.01
MIN_SECTION_POINTS = 5
"""The midrib: the centres of the level sets of this spacing along the leaf (of at least this
many points)."""
MIN_CLEAN_M = 0.05
CONTACT_M = 0.015
CONTACT_SHARE = 0.25
NARROWING = 0.7
"""A leaf is traced (from :data:`MIN_CLEAN_M` on) up to its first section with more than
:data:`CONTACT_SHARE` of its points within :data:`CONTACT_M` of another plant's or ambiguous,
or narrower than :data:`NARROWING` times (wider than its inverse times) the median of the four
before it: the neighbour holds one side of the leaf from there, or another leaf joins it."""
MAX_WIDTH_M = 0.15
"""Wider than this at its end a "leaf" is not one blade (leaves joined at the whorl)."""
FIT_M = 0.12
"""The ribbon's course and taper: fitted to the last this of its midrib."""
STEP_M = 0.01
PLANE_TOLERANCE_M = 0.01
EDGE_MARGIN_M = 0.005
MIN_STEP_POINTS = 5
"""A step holds the points within ``STEP_M / 2`` along the ribbon, its half width plus
:data:`EDGE_MARGIN_M` across and :data:`PLANE_TOLERANCE_M` off its plane; fewer than
:data:`MIN_STEP_POINTS` is a gap."""
FILL = 0.6
MAX_PATCHY_M = 0.2
"""A step whose points span :data:`FILL` of the ribbon's width, or of the span of the last
step that did (a leaf's tip narrows under the width its course keeps), is the leaf's; a patchy
stretch (at most :data:`MAX_PATCHY_M`) only when a filled step follows it. Only a step spanning
:data:`FILL` of the width re-centres the ribbon."""
MAX_SHIFT = 0.25
"""A step moves the ribbon across by at most this share of its half width."""
MIN_ARM_M = FIT_M
"""An arm is followed only when traced this far: a shorter trace cannot set its course."""
ARM_INSIDE = 0.9
"""An arm of a forked leaf: a leaf of the forks-split segmentation with this share of its
points in the unsplit leaf."""
MAX_GAP_M = 0.03
MIN_WIDTH_M = 0.01
MAX_REACH_M = 0.5
"""A ribbon stops after this long without points, below this width, or this far on."""
EDGE_REACH_M = 0.02
EDGE_GAP_M = 0.005
"""A step also takes the points of the leaf's surface that run on past its width without a
gap this wide, at most this far out (:func:`_edges`)."""
STRAY_NEIGHBOURS = 12
STRAY_SHARE = 0.75
STRAY_REACH_M = 0.01
STRAY_ROUNDS = 4
"""Near the points that moved (this close to those that moved last, for at most the rounds),
a point goes to the plant that holds this share of its nearest points of stems
(:func:`_with_strays`)."""


@dataclass
class Ribbon:
    """A leaf's course so far: ``centres_m`` (K, 3) its midrib, ``arc_m`` (K,) along it,
    ``widths_m`` (K,) its width there, ``normal`` (3,) its surface's normal at the end."""

    centres_m: NDArray[np.float64]
    arc_m: NDArray[np.float64]
    widths_m: NDArray[np.float64]
    normal: NDArray[np.float64]

    def predict(self, ahead_m: float) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """The centre (3,), unit direction (3,) and width ``ahead_m`` past the end: the
        parabola (a line with fewer than 6 centres) fitted to the last :data:`FIT_M`, and the
        taper fitted there, continued, never wider than the widest width there."""
        chosen = self.arc_m >= self.arc_m[-1] - FIT_M
        chosen[-2:] = True
        t = self.arc_m[chosen] - self.arc_m[-1]
        poly = np.polynomial.polynomial
        fit = poly.polyfit(t, self.centres_m[chosen], 2 if len(t) >= 6 else 1)
        centre = np.asarray(poly.polyval(ahead_m, fit), dtype=np.float64)
        slope = np.asarray(poly.polyval(ahead_m, poly.polyder(fit)), dtype=np.float64)
        taper = poly.polyfit(t, self.widths_m[chosen], 1)
        width = float(taper[0]) + min(float(taper[1]), 0.0) * ahead_m
        # the line fitted to a rise that levels off overshoots at its end, and each step's
        # width, fed back into the next fit, overshot again: a ribbon grew 1.3 cm in 41 steps
        width = min(width, float(self.widths_m[chosen].max()))
        norm = float(np.linalg.norm(slope))
        return centre, slope / max(norm, 1e-12), max(width, 0.0)

    def extend(self, centre_m: NDArray[np.float64], width_m: float) -> None:
        """One more centre (3,) of the midrib, with its width."""
        step = float(np.linalg.norm(centre_m - self.centres_m[-1]))
        self.centres_m = np.vstack([self.centres_m, centre_m])
        self.arc_m = np.append(self.arc_m, self.arc_m[-1] + step)
        self.widths_m = np.append(self.widths_m, width_m)


class Trace(NamedTuple):
    """A leaf traced: its ``ribbon``, (M,) the points it ``held`` and whether it ``forked``
    (its trace ends where it widens abruptly without meeting another plant)."""

    ribbon: Ribbon
    held: NDArray[np.bool_]
    forked: bool


def trace_leaf(
    points_m: NDArray[np.float64], touching: NDArray[np.bool_], radial_m: NDArray[np.float64]
) -> Trace | None:
    """The ribbon of a leaf's points (M, 3) from its base (the points nearest the stem: least
    ``radial_m`` (M,), their distance from the stem's axis) up to where it meets another plant
    (``touching`` (M,): near another plant's points or ambiguous) or its width jumps, and (M,)
    which points the leaf holds: those of its traced part more than :data:`FIT_M` before its
    end; ``None`` for a leaf too short or too wide to trace. The axis, not the foot: a stem
    leaning 15 degrees stands 11 cm off its foot 40 cm up, where a leaf pointing back over the
    foot is nearer it in plan view half way out than at its base."""
    base = np.flatnonzero(radial_m <= radial_m.min() + LEVEL_M)
    distance = LeafGraph.of(points_m).geodesic_m(base)
    levels = np.floor(distance / LEVEL_M).astype(np.intp)
    order = np.argsort(levels, kind="stable")
    _, starts = np.unique(levels[order], return_index=True)
    kept = [
        (part, share, level)
        for part, share, level in zip(
            np.split(points_m[order], starts[1:]),
            [float(t.mean()) for t in np.split(touching[order], starts[1:])],
            levels[order][starts],
            strict=True,
        )
        if len(part) >= MIN_SECTION_POINTS
    ]
    parts = [part for part, _, _ in kept]
    if len(parts) < 4:
        return None
    centres = np.array([part.mean(axis=0) for part in parts])
    tangents = centres[np.minimum(np.arange(len(parts)) + 1, len(parts) - 1)]
    tangents = tangents - centres[np.maximum(np.arange(len(parts)) - 1, 0)]
    counts = np.array([len(part) for part in parts], dtype=np.intp)
    widths = section_widths_m(np.concatenate(parts), counts, tangents)
    shares = np.array([share for _, share, _ in kept])
    first = _first_contact(widths, shares)
    if first < 4 or float(np.median(widths[first - 4 : first])) > MAX_WIDTH_M:
        return None
    forked = _forks_at(widths, shares, first)
    centres, widths = centres[:first], widths[:first]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(centres, axis=0), axis=1))])
    end = np.concatenate(parts[max(first - 5, 0) : first])
    spread = end - end.mean(axis=0)
    normal = np.linalg.eigh(spread.T @ spread)[1][:, 0]
    end_level = kept[first][2] if first < len(kept) else levels.max() + 1
    held = levels < end_level - round(FIT_M / LEVEL_M)
    return Trace(Ribbon(centres, arc, widths, normal), held, forked)


def _first_contact(widths_m: NDArray[np.float64], touching_share: NDArray[np.float64]) -> int:
    """Index of the first section (from :data:`MIN_CLEAN_M` on) that meets another plant or
    narrows or widens abruptly (:data:`NARROWING`); the number of sections when none does."""
    for i in range(round(MIN_CLEAN_M / LEVEL_M), len(widths_m)):
        if touching_share[i] > CONTACT_SHARE or _abrupt(widths_m, i):
            return i
    return len(widths_m)


def _abrupt(widths_m: NDArray[np.float64], i: int) -> bool:
    """Whether section ``i`` is narrower than :data:`NARROWING` times the median of the four
    before it, or wider than that median over :data:`NARROWING`."""
    before = _before(widths_m, i)
    return not NARROWING * before <= widths_m[i] <= before / NARROWING


def _forks_at(widths_m: NDArray[np.float64], touching_share: NDArray[np.float64], i: int) -> bool:
    """Whether the trace's end at section ``i`` is a fork: the leaf widens there abruptly
    without meeting another plant (another leaf lying over it joins it there)."""
    if i >= len(widths_m) or touching_share[i] > CONTACT_SHARE:
        return False
    return bool(widths_m[i] > _before(widths_m, i) / NARROWING)


def _before(widths_m: NDArray[np.float64], i: int) -> float:
    """The median width of the four sections before section ``i``."""
    return float(np.median(widths_m[max(i - 4, 0) : i]))


def follow(
    ribbon: Ribbon,
    points_m: NDArray[np.float64],
    tree: cKDTree,
    claimable: NDArray[np.bool_],
    held: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """The points (indices into ``points_m`` (N, 3), those ``claimable`` (N,)) that the
    ribbon's continuation runs through, step by step from its end, and (K,) how far past the
    end each was reached. ``tree``: the k-d tree of ``points_m``. ``held`` (N,): the points of
    a neighbour's leaf where that leaf is held; they steer the ribbon but do not fill a step
    (:func:`_step`)."""
    claimed: list[tuple[NDArray[np.intp], float]] = []
    pending: list[tuple[NDArray[np.intp], float]] = []
    start = float(ribbon.arc_m[-1])
    gap = patchy = 0.0
    ahead = STEP_M
    last = np.inf  # the span of the last filled step
    while gap < MAX_GAP_M and patchy <= MAX_PATCHY_M:
        past = float(ribbon.arc_m[-1]) - start + ahead
        centre, direction, width = ribbon.predict(ahead)
        if past > MAX_REACH_M or width < MIN_WIDTH_M:
            break
        step = _step(ribbon, centre, direction, width, points_m, tree, held)
        if step is None:
            gap, ahead = gap + STEP_M, ahead + STEP_M
            continue
        taken, span, moved, free_span = step
        # a tapering tip fills less and less of the width: measured against the last filled
        # step it is still the leaf (touching 4 x 4 seed 87's p23 lost its outer 2 709 points,
        # -13.1 cm, where its 9 cm wide leaf narrowed to 5)
        # a step filled only by a neighbour's held leaf is that leaf's, not this one's: a
        # leaf lying on its neighbour's leaf ends, and its ribbon, run on along the other
        # leaf, took the few points past where that leaf is held (a touching plot's p11,
        # 4 points of p10's 18 cm past its own leaf's tip, +11 cm)
        filled = free_span >= FILL * min(width, last)
        gap, ahead = 0.0, STEP_M
        pending.append((taken[claimable[taken]], past))
        if filled:
            claimed, pending, patchy, last = claimed + pending, [], 0.0, free_span
        else:
            patchy += STEP_M
        # but a narrow step does not steer: re-centred on a narrow strip beside it (a
        # neighbour's leaf) the ribbon follows that leaf away (first model, seed 6's p02)
        ribbon.extend(moved if span >= FILL * width else centre, width)
    if not claimed:
        return np.zeros(0, dtype=np.intp), np.zeros(0)
    index = np.concatenate([c for c, _ in claimed])
    return index, np.concatenate([np.full(len(c), d) for c, d in claimed])


def _step(
    ribbon: Ribbon,
    centre: NDArray[np.float64],
    direction: NDArray[np.float64],
    width: float,
    points_m: NDArray[np.float64],
    tree: cKDTree,
    held: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.intp], float, NDArray[np.float64], float] | None:
    """The points inside the ribbon's step at ``centre`` (3,) heading ``direction`` (3,), the
    span across the ribbon between their 5th and 95th percentiles, the centre moved onto
    them, and the same span of those not ``held`` (N,) (0 with fewer than
    :data:`MIN_STEP_POINTS` of them); ``None`` when the step holds fewer than
    :data:`MIN_STEP_POINTS`."""
    normal = ribbon.normal - (ribbon.normal @ direction) * direction
    normal /= max(float(np.linalg.norm(normal)), 1e-12)
    across_dir = np.cross(normal, direction)
    half = width / 2.0 + EDGE_MARGIN_M
    reach = half + EDGE_REACH_M
    radius = float(np.sqrt(reach**2 + STEP_M**2 + PLANE_TOLERANCE_M**2))
    near = np.asarray(tree.query_ball_point(centre, radius), dtype=np.intp)
    offset = points_m[near] - centre
    along, across, off = offset @ direction, offset @ across_dir, offset @ normal
    slab = np.abs(along) <= STEP_M / 2
    inside = slab & (np.abs(off) <= PLANE_TOLERANCE_M) & (np.abs(across) <= half)
    if inside.sum() < MIN_STEP_POINTS:
        return None
    low, high = np.percentile(across[inside], [5.0, 95.0])
    shift = float(np.clip(0.5 * (low + high), -MAX_SHIFT * half, MAX_SHIFT * half))
    on_plane = inside & (np.abs(off) <= PLANE_TOLERANCE_M / 2)  # not a sheet it lies on
    lift = float(np.median(off[on_plane])) if on_plane.any() else 0.0
    moved = centre + shift * across_dir + lift * normal
    taken = inside | _edges(across, off, slab, inside, half)
    span = free_span = float(high - low)
    free = inside if held is None else inside & ~held[near]
    if free is not inside and (free_count := int(free.sum())) < int(inside.sum()):
        # some of it a neighbour's held leaf: the rest's span
        free_span = 0.0
        if free_count >= MIN_STEP_POINTS:
            free_low, free_high = np.percentile(across[free], [5.0, 95.0])
            free_span = float(free_high - free_low)
    return near[taken], span, moved, free_span


def _edges(
    across: NDArray[np.float64],
    off: NDArray[np.float64],
    slab: NDArray[np.bool_],
    inside: NDArray[np.bool_],
    half: float,
) -> NDArray[np.bool_]:
    """The points of a step's ``slab`` beyond its ``half`` width (``across`` the ribbon) on
    either side that continue the leaf's surface outwards without a gap of
    :data:`EDGE_GAP_M`, at most :data:`EDGE_REACH_M` out: the leaf is wider than the ribbon's
    taper there (fitted near its base, never widening; a maize blade widens to its middle)
    and its edges would stay with the neighbour, set its width. The surface is the section's
    profile (``off`` the ribbon's plane against ``across``, a parabola fitted to the points
    ``inside``): a blade is channelled or rolled, its edges a centimetre or more off the plane
    where the middle lies on it; a point more than half the plane's tolerance off the profile
    is another sheet."""
    edge = np.zeros(len(across), dtype=bool)
    beside = slab & (np.abs(across) > half) & (np.abs(across) <= half + EDGE_REACH_M)
    if not beside.any() or inside.sum() < 3 * MIN_STEP_POINTS:
        return edge  # most steps: the leaf is no wider than the ribbon
    profile = np.polynomial.Polynomial.fit(across[inside], off[inside], 2)
    on_surface = slab & (np.abs(off - profile(across)) <= PLANE_TOLERANCE_M / 2)
    for sign in (1.0, -1.0):
        out = sign * across - half
        beyond = np.flatnonzero(beside & on_surface & (out > 0.0))
        if len(beyond) == 0:
            continue
        order = beyond[np.argsort(out[beyond])]
        steps = np.diff(np.concatenate([[0.0], out[order]]))
        gaps = np.flatnonzero(steps > EDGE_GAP_M)
        edge[order[: gaps[0] if len(gaps) else len(order)]] = True
    return edge


def _touching(
    points_m: NDArray[np.float64],
    tree: cKDTree,
    members: NDArray[np.intp],
    others: NDArray[np.bool_],
) -> NDArray[np.bool_]:
    """(len(members),) whether each of a plant's points (``members``, indices into
    ``points_m``, whose k-d tree is ``tree``) lies within :data:`CONTACT_M` of a point of
    another plant (``others`` (N,)); only the points around the plant are looked at."""
    own = points_m[members]
    low, high = own.min(axis=0), own.max(axis=0)
    reach = float(np.linalg.norm(high - low)) / 2.0 + CONTACT_M
    around = np.asarray(tree.query_ball_point((low + high) / 2.0, reach), dtype=np.intp)
    near = around[others[around]]
    if len(near) == 0:
        return np.zeros(len(members), dtype=bool)
    distance, _ = cKDTree(points_m[near]).query(own, distance_upper_bound=CONTACT_M)
    return np.isfinite(distance)  # type: ignore[no-any-return]


def _trace_plants(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    ambiguous: NDArray[np.bool_],
    feet_m: NDArray[np.float64],
    traced: NDArray[np.intp],
    tree: cKDTree,
) -> tuple[list[tuple[int, Ribbon]], NDArray[np.bool_]]:
    """The ribbons of the ``traced`` stems' leaves (with their stem) and (N,) the points their
    leaves hold (:func:`trace_leaf`)."""
    ribbons: list[tuple[int, Ribbon]] = []
    held = np.zeros(len(points_m), dtype=bool)
    on_stems = (labels >= 0) & (labels < len(feet_m))
    touching = ambiguous.copy()
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], [traced, traced + 1])
    for stem, start, stop in zip(traced, *bounds, strict=True):
        members = order[start:stop]
        # Leaves lying over each other near the stem stay one branch here, split at their
        # fork only where the branch's trace ends at it or fails: split everywhere, a short arm's
        # trace gave touching seed 10's p07 a neighbour's leaf (+11.7 cm; width RMSE over
        # 48 touching inputs 1.67 cm unsplit, 1.77 split; RECONSTRUCTION.md)
        own = points_m[members]
        # The stem-like axis, not the traced one (organs.fit_stem_axis): traced, the bench's
        # touching widths moved 1.74 -> 1.87 cm mean RMSE over seeds 0-11, knife edges
        # falling both ways (RECONSTRUCTION.md, "Organs")
        branches = Branches.of(own, feet_m[stem], trace=False)
        organs = branches.organs(split_forks=False)
        touching[members] |= _touching(points_m, tree, members, on_stems & (labels != stem))
        near = touching[members]  # which of the plant's points touch another plant
        arms: list[NDArray[np.intp]] | None = None
        radial = branches.radial  # from the stem's axis
        for leaf in organs.leaves:
            whole = trace_leaf(own[leaf], near[leaf], radial[leaf])
            traces = [(leaf, whole)]
            if whole is None or whole.forked:
                # its trace stopped where another leaf joins it, or it is too wide to trace:
                # each arm is traced on its own (touching seed 94's p28: the arm that meets
                # the neighbour; seed 1's p14: leaves joined near the stem)
                if arms is None:
                    arms = branches.organs(split_forks=True).leaves
                split = [
                    (arm, trace_leaf(own[arm], near[arm], radial[arm]))
                    for arm in _arms_of(leaf, arms, len(members))
                ]
                reach = max((f.ribbon.arc_m[-1] for _, f in split if f is not None), default=0.0)
                if reach > (0.0 if whole is None else whole.ribbon.arc_m[-1]):
                    traces = split
            for part, found in traces:
                if found is None:
                    continue
                held[members[part[found.held]]] = True
                if len(traces) == 1 or found.ribbon.arc_m[-1] >= MIN_ARM_M:
                    ribbons.append((int(stem), found.ribbon))
    return ribbons, held


def _arms_of(
    leaf: NDArray[np.intp], split: list[NDArray[np.intp]], size: int
) -> list[NDArray[np.intp]]:
    """The leaves of the forks-split segmentation ``split`` that lie within ``leaf`` (both
    indices into the same plant's ``size`` points), when it split ``leaf`` into two or more."""
    inside = np.zeros(size, dtype=bool)
    inside[leaf] = True
    arms = [arm for arm in split if len(arm) and inside[arm].mean() >= ARM_INSIDE]
    return arms if len(arms) >= 2 else []


def follow_leaves(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    ambiguous: NDArray[np.bool_],
    feet_m: NDArray[np.float64],
) -> NDArray[np.intp]:
    """The leaves of every plant with a point ``ambiguous`` (N,) followed across their
    contacts: ``labels`` (N,) (the stem of each point, 0..S-1 for the stems whose feet are
    ``feet_m`` (S, 3); other labels are left alone) are changed in place where a leaf's ribbon
    runs on through a neighbour's points, with the points its steps left among them
    (:func:`_with_strays`). Returns the points that changed hands. Every such plant, not only
    those over the report's flag: a plant whose share of ambiguous points slipped under the
    flag lost its ribbon, and its leaf, on a 0.1 % change."""
    stems = len(feet_m)
    on_stems = (labels >= 0) & (labels < stems)
    traced = np.flatnonzero(np.bincount(labels[on_stems & ambiguous], minlength=stems))
    if len(traced) == 0:
        return np.zeros(0, dtype=np.intp)
    tree = cKDTree(points_m)
    ribbons, held = _trace_plants(points_m, labels, ambiguous, feet_m, traced, tree)
    claimer = np.full(len(points_m), -1, dtype=np.intp)
    nearest = np.full(len(points_m), np.inf)
    for stem, ribbon in ribbons:
        others = on_stems & (labels != stem)
        claimable = others & (~held | ambiguous)
        taken, past = follow(ribbon, points_m, tree, claimable, others & ~claimable)
        better = past < nearest[taken]
        claimer[taken[better]] = stem
        nearest[taken[better]] = past[better]
    won = np.flatnonzero(claimer >= 0)
    labels[won] = claimer[won]
    movable = on_stems & (~held | ambiguous)
    return _with_strays(points_m, tree, labels, won, movable, on_stems)


def _with_strays(
    points_m: NDArray[np.float64],
    tree: cKDTree,
    labels: NDArray[np.intp],
    won: NDArray[np.intp],
    movable: NDArray[np.bool_],
    on_stems: NDArray[np.bool_],
) -> NDArray[np.intp]:
    """``won`` and the points left scattered among the points around them: a ribbon's steps,
    1 cm slabs across a curving leaf, miss a point here and there, and each one left to the
    neighbour stretches the neighbour's width as far as the leaf runs. Near the points that
    moved, a ``movable`` point goes to the plant that holds at least :data:`STRAY_SHARE` of its
    :data:`STRAY_NEIGHBOURS` nearest points of stems (``on_stems``); repeated
    (:data:`STRAY_ROUNDS` at most) around the points that moved. Where two plants' points meet
    along a line, or lie in two sheets over each other, each has about half of the others'
    neighbours, and stays. ``labels`` is changed in place."""
    taken = np.zeros(len(points_m), dtype=bool)
    taken[won] = True
    fresh = won
    for _ in range(STRAY_ROUNDS):
        if len(fresh) == 0:
            break
        around = np.zeros(len(points_m), dtype=bool)
        balls = tree.query_ball_point(points_m[fresh], STRAY_REACH_M, return_sorted=False)
        around[np.concatenate(balls)] = True
        candidates = np.flatnonzero(around & movable & ~taken)
        if len(candidates) == 0:
            break
        _, near = tree.query(points_m[candidates], k=STRAY_NEIGHBOURS + 1)
        near = near[:, 1:]
        counted = on_stems[near]
        other = np.where(counted & (labels[near] != labels[candidates][:, None]), labels[near], -1)
        best = np.full(len(candidates), -1, dtype=np.intp)
        votes = np.zeros(len(candidates), dtype=np.intp)
        for column in other.T:  # the plant that holds most of them
            count = (other == column[:, None]).sum(axis=1)
            better = (column >= 0) & (count > votes)
            best[better], votes[better] = column[better], count[better]
        moves = (votes > 0) & (votes >= STRAY_SHARE * counted.sum(axis=1))
        fresh = candidates[moves]
        labels[fresh] = best[moves]
        taken[fresh] = True
    return np.flatnonzero(taken)
