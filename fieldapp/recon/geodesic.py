"""Every plant point to the stem it grows from, by distance *along the plant*.

The plant cloud becomes a graph: occupied ``voxel_m`` voxels (their centroids) joined to their
26 neighbours, each edge as long as the centroids are apart. From each stem foot a Dijkstra
search runs over the voxels within ``reach_m`` (plan view) of it, so the work per plant is
bounded and the whole step stays linear in the number of plants. A voxel goes to the stem it
is geodesically nearest to: a leaf that crosses into a neighbour's space is reached along
itself from its own stem, not across the gap from the neighbour's. A voxel that a second stem
reaches within ``ambiguity_margin_m`` of the first is *ambiguous* (it could belong to either).

A path that passes from one surface onto another at an angle (onto a leaf that touches or
crosses the one it runs on) pays for the bend (:func:`bend_weighted`): a leaf is followed as
one smooth sheet from its base, where it leaves its stem nearly along it, while a neighbour's
path that reaches it across a contact pays at the contact. With ``sheet_aware``, where two
sheets cross the bend is judged against the sheet a path is on rather than the voxels'
normals blurred from both (:func:`crossing_sheets`, :func:`sheet_graph`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix, csr_matrix, identity
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from fieldapp.recon.filters import voxel_keys
from fieldapp.recon.grid import NodeClaims

UNREACHED = -1
LYING_M = 0.04
"""A leaf's end lying on the soil, this high above its foot's ground at most, is not weighed
by :func:`leaf_ends`: it lies beyond the foot, off the way to the plant it grows from."""
LEAF_END_SIZE = 0.45
"""A leaf's end holds at most this share of the voxels the plant it grows from holds
(:func:`leaf_ends`; measured at most 0.36 on the simulated plots with leaves down to the soil):
a plant of one leaf whose leaf touches its neighbour's lies on the way between their feet as
much as a leaf's end does, but is not that much smaller (0.54-0.83 in the synthetic pairs of
``tests/fieldapp/recon/touching.py``)."""
SHEET_THICKNESS = 0.06
SHEET_RADIUS_M = 0.035
SHEET_MIN_ANGLE_DEG = 35.0
SHEET_TOLERANCE_M = 0.005
BIN_BLOCK = 16_384
"""Voxels whose normals are binned to the 200 directions at a time (:func:`crossing_sheets`)."""
EDGE_BLOCK = 262_144
"""Edges of the voxel graph whose (voxel, sheet) state pairs are costed at a time
(:func:`sheet_graph`)."""

_HALF_NEIGHBOURHOOD = np.array(
    [offset for offset in itertools.product((-1, 0, 1), repeat=3) if offset > (0, 0, 0)],
    dtype=np.int64,
)


@dataclass(frozen=True)
class VoxelGraph:
    """Occupied voxels: ``centres_m`` (V, 3) centroids, ``point_voxel`` (N,) the voxel of each
    point, ``edges`` the symmetric (V, V) CSR matrix of centroid distances."""

    centres_m: NDArray[np.float64]
    point_voxel: NDArray[np.intp]
    edges: csr_matrix

    @cached_property
    def plan_tree(self) -> cKDTree:
        """The plan-view k-d tree of the voxel centres, built once for every step that asks it
        (the assignment, the crossing sheets, the leaf ends)."""
        return cKDTree(self.centres_m[:, :2])

    @cached_property
    def longest_m(self) -> float:
        """The graph's longest step (0 without steps): the steps across gaps are longer."""
        return float(self.edges.data.max(initial=0.0))


@dataclass(frozen=True)
class Assignment:
    """Per point: ``stem`` (N,) index of its stem (or :data:`UNREACHED`), ``ambiguous`` (N,)
    whether a second stem reaches it almost as soon, ``runner_up`` (N,) the stem that reaches
    it second (or :data:`UNREACHED`)."""

    stem: NDArray[np.intp]
    ambiguous: NDArray[np.bool_]
    runner_up: NDArray[np.intp]


def _pack(cells: NDArray[np.int64]) -> NDArray[np.int64]:
    shifted = cells + (1 << 20)
    return (shifted[:, 0] << 42) | (shifted[:, 1] << 21) | shifted[:, 2]


def voxel_neighbours(
    points_m: NDArray[np.float64], voxel_m: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], int]:
    """The occupied ``voxel_m`` voxels of ``points_m`` (N, 3): (N,) each point's voxel, the
    pairs of 26-neighbouring voxels (each pair once: rows, cols) and the number of voxels.
    Voxels are numbered in the order of their keys (:func:`filters.voxel_keys`, which also
    checks the extent)."""
    keys, first, inverse = np.unique(
        voxel_keys(points_m, voxel_m), return_index=True, return_inverse=True
    )
    unique_cells = np.floor(points_m[first] / voxel_m).astype(np.int64)  # packed as _pack packs
    rows, cols = [], []
    for offset in _HALF_NEIGHBOURHOOD:
        wanted = _pack(unique_cells + offset)
        at = np.clip(np.searchsorted(keys, wanted), 0, len(keys) - 1)
        found = keys[at] == wanted
        rows.append(np.flatnonzero(found))
        cols.append(at[found])
    return inverse.ravel().astype(np.intp), np.concatenate(rows), np.concatenate(cols), len(keys)


def voxel_graph(
    points_m: NDArray[np.float64], voxel_m: float, max_edge_m: float | None = None
) -> VoxelGraph:
    """The graph of the occupied voxels of ``points_m`` (N, 3): each joined to those of its 26
    neighbours whose centroid is within ``max_edge_m`` (default 1.5 voxels) of its own, so
    two leaves passing a few centimetres apart are not joined through a corner."""
    max_edge_m = 1.5 * voxel_m if max_edge_m is None else max_edge_m
    inverse, row, col, n = voxel_neighbours(points_m, voxel_m)
    counts = np.bincount(inverse, minlength=n).astype(np.float64)
    centres = np.stack([np.bincount(inverse, points_m[:, a], n) / counts for a in range(3)], 1)
    length = np.linalg.norm(centres[row] - centres[col], axis=1)
    short = length <= max_edge_m
    row, col, length = row[short], col[short], length[short] + 1e-9
    edges = coo_matrix(
        (
            np.concatenate([length, length]),
            (np.concatenate([row, col]), np.concatenate([col, row])),
        ),
        shape=(n, n),
    ).tocsr()
    return VoxelGraph(centres, inverse, edges)


def surface_normals(graph: VoxelGraph) -> NDArray[np.float64]:
    """(V, 3) unit normal of the surface at each voxel: the direction of least spread of its
    own and its graph neighbours' centroids (about 3 cm across at 1 cm voxels)."""
    return _ring_spread(graph)[1][:, :, 0]


def _ring_spread(graph: VoxelGraph) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Eigenvalues (V, 3), ascending, and eigenvectors (V, 3, 3) of the spread of each voxel's
    own and its graph neighbours' centroids."""
    ring = graph.edges.copy()
    ring.data[:] = 1.0
    ring = (ring + identity(ring.shape[0], format="csr")).tocsr()
    count = np.asarray(ring.sum(axis=1)).ravel()
    c = graph.centres_m - graph.centres_m.mean(axis=0)  # centred: no cancellation
    mean = (ring @ c) / count[:, None]
    covariance = np.empty((len(c), 3, 3))
    for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):
        covariance[:, i, j] = ring @ (c[:, i] * c[:, j]) / count - mean[:, i] * mean[:, j]
        covariance[:, j, i] = covariance[:, i, j]
    values, vectors = np.linalg.eigh(covariance)  # eigenvalues ascending
    return values, vectors


def bend_weighted(graph: VoxelGraph, bend_penalty_m: float) -> VoxelGraph:
    """``graph`` with each edge costing ``bend_penalty_m`` times (1 - |cos|) of the angle
    between its voxels' surface normals on top of its length. Along one leaf the normal turns
    slowly and the bends cost next to nothing (3 % of a 70 cm arching leaf's length); where a
    path passes from one surface onto another at an angle (onto a leaf it touches or crosses)
    it pays up to the full penalty on the sharpest edges. Surfaces that touch with the same
    normal (a leaf lying flat on another) cost nothing to pass between."""
    return VoxelGraph(graph.centres_m, graph.point_voxel, _bend_edges(graph, bend_penalty_m)[0])


def _bend_edges(
    graph: VoxelGraph, bend_penalty_m: float, keep_bend: bool = False
) -> tuple[csr_matrix, csr_matrix | None]:
    """The edges of :func:`bend_weighted` and, with ``keep_bend``, the bend part of each, laid
    out as the edges."""
    normals = surface_normals(graph)
    edges = graph.edges.tocoo()
    cosine = np.abs(np.sum(normals[edges.row] * normals[edges.col], axis=1))
    bend = bend_penalty_m * (1.0 - np.minimum(cosine, 1.0))
    return _same_layout(edges.data + bend, bend, edges.row, edges.col, edges.shape, keep_bend)


def _same_layout(
    cost: NDArray[np.float64],
    bend: NDArray[np.float64],
    row: NDArray[np.intp],
    col: NDArray[np.intp],
    shape: tuple[int, int],
    keep_bend: bool,
) -> tuple[csr_matrix, csr_matrix | None]:
    """``cost`` and, with ``keep_bend``, ``bend`` on the edges (``row``, ``col``) as CSR
    matrices whose entries line up one for one (the bend kept off zero while converting, so
    none is dropped)."""
    weighted = coo_matrix((cost, (row, col)), shape=shape).tocsr()
    if not keep_bend:
        return weighted, None
    part = coo_matrix((bend + 1.0, (row, col)), shape=shape).tocsr()
    part.data -= 1.0
    return weighted, part


@dataclass(frozen=True)
class Sheets:
    """The sheets that cross at some voxels (two leaves in an X): ``voxel`` (K,) and ``normal``
    (K, 3), one row per sheet, each such voxel in two or three rows."""

    voxel: NDArray[np.intp]
    normal: NDArray[np.float64]


def _directions(count: int) -> NDArray[np.float64]:
    """``count`` unit vectors spread evenly over the upper hemisphere (a Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    z = 1.0 - i / count
    angle = np.pi * (1.0 + 5.0**0.5) * i
    r = np.sqrt(1.0 - z**2)
    return np.column_stack([r * np.cos(angle), r * np.sin(angle), z])


def crossing_sheets(
    graph: VoxelGraph,
    thickness: float = SHEET_THICKNESS,
    radius_m: float = SHEET_RADIUS_M,
    min_angle_deg: float = SHEET_MIN_ANGLE_DEG,
    tolerance_m: float = SHEET_TOLERANCE_M,
    within: NDArray[np.bool_] | None = None,
    ring: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> Sheets:
    """The voxels where two or three sheets cross (two leaves in an X, a leaf across a stem),
    each with its sheets' normals.

    A voxel's ring normal (:func:`surface_normals`) is the least spread of about 3 cm of
    centroids; where two sheets cross it is neither sheet's normal and the ring is *thick*
    (its least spread over the total above ``thickness``; one sheet, even curved, is thin over
    3 cm). The sheets at a thick voxel are read off the *thin* voxels within ``radius_m``,
    whose normals are one sheet's each: the directions (one of 200 over the hemisphere) that
    most of their normals lie within 12 degrees of, up to three, each ``min_angle_deg`` or more
    from the others and held by 3 voxels or more, each sheet's normal the mean of those normals
    and its plane passing within ``tolerance_m`` of the voxel's centroid. A thick voxel
    with fewer than two such sheets (a stem, a leaf's fold, a sheet's edge beside another) is
    left as it is; ``within`` (V,) limits the search to some voxels; ``ring``: the graph's
    :func:`_ring_spread`, when the caller has it already."""
    values, vectors = _ring_spread(graph) if ring is None else ring
    normals = vectors[:, :, 0]
    total = values.sum(axis=1)
    thick = values[:, 0] > thickness * total
    if within is not None:  # only there (the voxels two stems could reach)
        thick &= within
    candidates, thin = np.flatnonzero(thick), np.flatnonzero(~thick & (total > 0.0))
    nothing = Sheets(np.empty(0, dtype=np.intp), np.empty((0, 3)))
    if len(candidates) == 0 or len(thin) == 0:
        return nothing
    near = cKDTree(graph.centres_m[thin]).query_ball_point(graph.centres_m[candidates], radius_m)
    counts = np.fromiter((len(n) for n in near), dtype=np.intp, count=len(near))
    if counts.sum() == 0:
        return nothing
    owner = np.repeat(np.arange(len(candidates)), counts)
    neighbour = thin[
        np.fromiter(itertools.chain.from_iterable(near), dtype=np.intp, count=int(counts.sum()))
    ]
    n, at = normals[neighbour], graph.centres_m[neighbour]
    k, directions = len(candidates), _directions(200)
    close, apart = np.cos(np.radians(12.0)), np.cos(np.radians(min_angle_deg))
    half = np.cos(np.radians(min_angle_deg / 2.0))
    # each neighbouring thin voxel's normal binned to its nearest direction, once; a
    # direction's votes are the normals binned within 12 degrees of it
    binned = np.zeros(len(normals), dtype=np.intp)
    used = np.unique(neighbour)
    for start in range(0, len(used), BIN_BLOCK):  # (block, 200): not (every thin voxel, 200)
        rows = used[start : start + BIN_BLOCK]
        binned[rows] = np.argmax(np.abs(normals[rows] @ directions.T), axis=1)
    counted = np.bincount(
        owner * len(directions) + binned[neighbour], minlength=k * len(directions)
    )
    neighbouring = (np.abs(directions @ directions.T) > close).astype(np.float64)
    votes = counted.reshape(k, len(directions)).astype(np.float64) @ neighbouring
    centre = graph.centres_m[candidates]
    sheets = np.zeros((k, 3, 3))
    through = np.zeros((k, 3), dtype=bool)
    for p in range(3):
        best = np.argmax(votes, axis=1)
        d = directions[best]
        along = np.sum(n * d[owner], axis=1)
        member = np.abs(along) > half  # a sheet's normals: within half the angle apart
        size = np.bincount(owner[member], minlength=k)
        signed = n[member] * np.sign(along[member])[:, None]
        summed = np.stack([np.bincount(owner[member], signed[:, a], k) for a in range(3)], 1)
        normal = summed / np.maximum(np.linalg.norm(summed, axis=1, keepdims=True), 1e-12)
        total_at = np.stack([np.bincount(owner[member], at[member, a], k) for a in range(3)], 1)
        mean = total_at / np.maximum(size, 1)[:, None]
        # a sheet of this voxel's: held by 3 thin voxels or more, its plane through the voxel
        through[:, p] = (size >= 3) & (
            np.abs(np.sum((centre - mean) * normal, axis=1)) <= tolerance_m
        )
        sheets[:, p] = normal
        votes *= np.abs(d @ directions.T) < apart  # no further sheet within min_angle_deg
    held = through.sum(axis=1)
    two = held >= 2
    voxel, normal_rows = [], []
    for p in range(3):
        keep = two & through[:, p]
        voxel.append(candidates[keep])
        normal_rows.append(sheets[keep, p])
    return Sheets(np.concatenate(voxel), np.concatenate(normal_rows))


def sheet_graph(
    graph: VoxelGraph,
    bend_penalty_m: float,
    sheets: Sheets,
    normals: NDArray[np.float64] | None = None,
    keep_bend: bool = False,
) -> tuple[csr_matrix, NDArray[np.intp], csr_matrix | None]:
    """The graph of :func:`bend_weighted` over (voxel, sheet) states: a voxel where sheets
    cross (``sheets``) has one state per sheet, every other voxel one with its surface normal.
    A step between two states costs its length plus ``bend_penalty_m`` times (1 - |cos|) of
    the angle between the states' normals, so a path that runs through a crossing on its own
    sheet pays nothing for the crossing, and one that turns onto the other sheet pays the bend
    between the two. A step to or from a sheet's state also pays as a bend by its angle to
    the sheet's plane (a step along the sheet pays next to nothing, one across to a sheet
    stacked over it the full bend). Returns the (S, S) edges, each state's voxel (S,), in
    voxel order, and with ``keep_bend`` the bend part of each edge (laid out as the edges, else
    None). ``normals``: the graph's :func:`surface_normals`, when the caller has them."""
    normals = surface_normals(graph) if normals is None else normals
    voxels = len(normals)
    split = np.zeros(voxels, dtype=bool)
    split[sheets.voxel] = True
    state_voxel = np.concatenate([np.flatnonzero(~split), sheets.voxel])
    state_normal = np.concatenate([normals[~split], sheets.normal])
    order = np.argsort(state_voxel, kind="stable")
    state_voxel, state_normal = state_voxel[order], state_normal[order]
    count = np.bincount(state_voxel, minlength=voxels)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    edges = graph.edges.tocoo()
    pairs = count[edges.row] * count[edges.col]  # one state pair per edge but at crossings
    starts = np.cumsum(pairs) - pairs
    total = int(pairs.sum())
    row, col = np.empty(total, dtype=np.intp), np.empty(total, dtype=np.intp)
    cost, bend = np.empty(total), np.empty(total)
    for lo in range(0, len(pairs), EDGE_BLOCK):  # a block of edges at a time: (E, 3) arrays
        hi = min(lo + EDGE_BLOCK, len(pairs))  # of a big plot's millions of edges were 0.5 GB
        block = pairs[lo:hi]
        at = slice(int(starts[lo]), int(starts[lo] + block.sum()))
        edge = np.repeat(np.arange(lo, hi), block)
        k = np.arange(len(edge)) - np.repeat(starts[lo:hi] - starts[lo], block)
        across = count[edges.col[edge]]
        r = first[edges.row[edge]] + k // across
        c = first[edges.col[edge]] + k % across
        cosine = np.abs(np.sum(state_normal[r] * state_normal[c], axis=1))
        length = edges.data[edge]
        summed = length + bend_penalty_m * (1.0 - np.minimum(cosine, 1.0))
        # a step out of a crossing's sheet pays as a bend by its angle to the sheet's plane:
        # two sheets stacked 1-3 cm apart are no X, and stepping from one to the other leaves
        # both
        step = graph.centres_m[edges.col[edge]] - graph.centres_m[edges.row[edge]]
        step /= np.maximum(np.linalg.norm(step, axis=1, keepdims=True), 1e-12)
        out = np.zeros(len(r))
        for end in (r, c):
            on = split[state_voxel[end]]
            sine = np.minimum(np.abs(np.sum(step[on] * state_normal[end[on]], axis=1)), 1.0)
            out[on] = np.maximum(out[on], 1.0 - np.sqrt(1.0 - sine**2))
        summed += bend_penalty_m * out
        row[at], col[at], cost[at], bend[at] = r, c, summed, summed - length
    states = len(state_voxel)
    weighted, bend_edges = _same_layout(cost, bend, row, col, (states, states), keep_bend)
    return weighted, state_voxel, bend_edges


@dataclass(frozen=True)
class StateGraph:
    """What a path pays to step over the voxel graph: ``edges`` (S, S) between states (a
    voxel's, or one per sheet where sheets cross), ``state_voxel`` (S,) each state's voxel, in
    voxel order, and ``bend`` the bend part of each edge (laid out as ``edges``) where a collar
    is to be free of it, else None."""

    edges: csr_matrix
    state_voxel: NDArray[np.intp]
    bend: csr_matrix | None


def state_graph(
    graph: VoxelGraph,
    stems_xy_m: NDArray[np.float64],
    seed_radius_m: float,
    bend_penalty_m: float = 0.0,
    sheet_aware: bool = False,
    keep_bend: bool = False,
) -> StateGraph:
    """The costs :func:`assign_to_stems` searches over (its arguments of the same names);
    built once, it serves every assignment over the same stems or a subset of them."""
    voxels = len(graph.centres_m)
    shared = _shared(graph, graph.plan_tree, stems_xy_m, seed_radius_m) if sheet_aware else None
    if bend_penalty_m > 0.0 and shared is not None and shared.any():
        ring = _ring_spread(graph)  # once, for the sheets and the states' normals
        sheets = crossing_sheets(graph, within=shared, ring=ring)
        edges, state_voxel, bend = sheet_graph(
            graph, bend_penalty_m, sheets, ring[1][:, :, 0], keep_bend
        )
        return StateGraph(edges, state_voxel, bend)
    if bend_penalty_m > 0.0:
        edges, bend = _bend_edges(graph, bend_penalty_m, keep_bend)
        return StateGraph(edges, np.arange(voxels, dtype=np.intp), bend)
    return StateGraph(graph.edges, np.arange(voxels, dtype=np.intp), None)


@dataclass(frozen=True)
class Junctions:
    """Steps across gaps that a stem's own paths may take near it (:func:`assign_to_stems`):
    between voxels more than the graph's longest step and at most ``gap_m`` apart, both within
    ``radius_m`` (plan view) of the stem, each costing its length plus ``penalty_m``."""

    radius_m: float
    gap_m: float
    penalty_m: float


def assign_to_stems(
    graph: VoxelGraph,
    stems_xy_m: NDArray[np.float64],
    seed_radius_m: float,
    seed_height_m: float,
    reach_m: float,
    ambiguity_margin_m: float,
    inward_penalty: float = 0.0,
    bend_penalty_m: float = 0.0,
    sheet_aware: bool = False,
    collar_radius_m: float = 0.0,
    collar_height_m: float = 0.0,
    junctions: Junctions | None = None,
    costs: StateGraph | None = None,
) -> Assignment:
    """Each voxel to the stem (``stems_xy_m`` (S, 2)) it is geodesically nearest to.

    A stem's sources are the voxels within ``seed_radius_m`` of its foot in plan view and no
    higher than ``seed_height_m`` above the lowest of them. Each step back towards the stem
    (in plan view) costs ``inward_penalty`` times its inward length on top of its length
    (:func:`_outward`; not within ``seed_radius_m``, the stem's own column), and passing from
    one surface onto another up to ``bend_penalty_m`` (:func:`bend_weighted`); with
    ``sheet_aware``, judged against the sheet the path is on where two sheets cross
    (:func:`sheet_graph`). With ``collar_radius_m`` > 0 a stem's own
    paths pay no bend on steps within that (plan view) of the stem and no higher than
    ``collar_height_m`` above its highest source (:func:`_free_collar`): the turn from a stem
    onto its own leaf; every other stem's paths still pay there. Off by default: measured on
    both plant models in ``docs/notes/touching-canopies.md`` ("The collar, per source").

    With ``junctions``, a stem's own paths may also step across the gaps near it
    (:class:`Junctions`): a leaf whose base no camera saw whole, cut from its stem in the
    graph, is reached from its stem across the gap, at a price (``penalty_m``) that only a
    neighbour reaching it by a longer way, across a contact, does not beat. ``costs``: the
    :func:`state_graph` of these stems (or of a set they are part of), when the caller has it."""
    voxels = len(graph.centres_m)
    tree = graph.plan_tree
    collar = collar_radius_m > 0.0
    if costs is None:
        costs = state_graph(
            graph, stems_xy_m, seed_radius_m, bend_penalty_m, sheet_aware, keep_bend=collar
        )
    edges, state_voxel, bend = costs.edges, costs.state_voxel, costs.bend
    count = np.bincount(state_voxel, minlength=voxels)  # each voxel's states, in voxel order
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    best = np.full(voxels, np.inf)
    second = np.full(voxels, np.inf)
    owner = np.full(voxels, UNREACHED, dtype=np.intp)
    runner_up = np.full(voxels, UNREACHED, dtype=np.intp)
    position = np.full(len(state_voxel), -1, dtype=np.intp)  # global -> local state index
    for index, xy in enumerate(stems_xy_m):
        local = np.sort(np.asarray(tree.query_ball_point(xy, reach_m), dtype=np.intp))
        sources = _sources(graph.centres_m[local], xy, seed_radius_m, seed_height_m)
        if len(sources) == 0:
            continue
        n = count[local]
        offset = np.concatenate([[0], np.cumsum(n)[:-1]])  # each local voxel's first state
        states = np.repeat(first[local] - offset, n) + np.arange(int(n.sum()))
        sources = np.repeat(offset[sources], n[sources]) + (
            np.arange(int(n[sources].sum()))
            - np.repeat(np.cumsum(n[sources]) - n[sources], n[sources])
        )
        position[states] = np.arange(len(states))
        sub = _subgraph(edges, states, position)
        at = graph.centres_m[state_voxel[states]]
        if bend is not None and collar:
            top = float(at[sources, 2].max()) + collar_height_m  # above the stem's foot
            sub = _free_collar(sub, _subgraph(bend, states, position), at, xy, collar_radius_m, top)
        if junctions is not None:
            sub = _across_junctions(sub, at, xy, junctions, graph.longest_m)
        sub = _outward(sub, at, xy, inward_penalty, seed_radius_m)
        position[states] = -1
        by_state = dijkstra(sub, directed=True, indices=sources, min_only=True)
        distance = np.minimum.reduceat(by_state, offset) if len(states) > len(local) else by_state
        reached = np.isfinite(distance)
        where, d = local[reached], distance[reached]
        better = d < best[where]
        runs_up = ~better & (d < second[where])
        runner_up[where[better]] = owner[where[better]]
        runner_up[where[runs_up]] = index
        second[where] = np.where(better, best[where], np.minimum(second[where], d))
        owner[where[better]] = index
        best[where[better]] = d[better]
    reached_twice = np.isfinite(second)
    ambiguous = np.zeros(voxels, dtype=bool)
    ambiguous[reached_twice] = second[reached_twice] - best[reached_twice] < ambiguity_margin_m
    of = graph.point_voxel
    return Assignment(owner[of], ambiguous[of], runner_up[of])


def leaf_ends(
    graph: VoxelGraph,
    feet_m: NDArray[np.float64],
    assignment: Assignment,
    seed_radius_m: float,
    seed_height_m: float,
    reach_m: float,
    share: float,
    slack_m: float,
    claims: NodeClaims | None = None,
    share_off_grid: float = 1.0,
) -> NDArray[np.intp]:
    """(S,) for each stem (``feet_m`` (S, 3): its foot's xy and local ground) the stem it is
    merged into (itself when kept): a stem whose voxels more than :data:`LYING_M` above its
    ground lie, ``share`` of them or more, along the way between its foot and the foot of the
    stem that reaches them second (the two feet's plain path lengths to the voxel, no bend or
    inward cost, at most ``slack_m`` more than the shortest way between the feet), and which
    holds at most :data:`LEAF_END_SIZE` of that stem's voxels. Where a planting grid places the
    stems (``claims``, :func:`fieldapp.recon.grid.node_claims`), a stem off it needs
    ``share_off_grid`` of them on the way, and only to be no larger than that stem: the plan
    says no plant stands there. So does a stem whose nearest node is that stem's too: the plan
    has one plant there, and which of the two stands nearer the node says nothing (an
    independent renderer's leaf end 13 cm from its stem stood 5.7 cm from the node, the stem
    8.4 cm). A stem at no node that falls short is weighed again voxel by voxel, each voxel
    against the stem that reaches *it* second (:func:`_share_on_the_way`): two plants' leaves
    come down crossing at one spot between them make one stem, half of it on the way to each
    plant (an independent renderer's: 0.45 against one of them, 0.83 so; real plants at most
    0.6 either way, docs/RECONSTRUCTION.md "Two leaves come down crossing, off the grid").

    A leaf that arches over and comes down to the soil fills the band above the ground as a
    stem does; its "plant" is the leaf's end, a strip on the way between its foot and the plant
    it grows from (its tip lying on the soil aside). A plant, even a seedling touching a
    neighbour, has a leaf branching off that way. Measured (share of the standing voxels within
    0.2 m of the way): 124 of 128 leaf ends on ten simulated plots with leaves down to the soil
    0.90 or more (the other four 0.69-0.83: they hold points off that way too); the plants of 25
    touching and seedling plots at most 0.46; two-leaved seedlings whose leaf a tall plant's
    runs through at most 0.80 (docs/RECONSTRUCTION.md "Leaves down to the soil")."""
    stems = len(feet_m)
    stems_xy_m = feet_m[:, :2]
    into = np.arange(stems, dtype=np.intp)
    voxels = len(graph.centres_m)
    if stems < 2:
        return into
    owner = np.full(voxels, UNREACHED, dtype=np.intp)
    owner[graph.point_voxel] = assignment.stem
    runner_up = np.full(voxels, UNREACHED, dtype=np.intp)
    runner_up[graph.point_voxel] = assignment.runner_up
    size = np.bincount(owner[owner >= 0], minlength=stems)
    tree = graph.plan_tree
    distances: dict[int, NDArray[np.float64]] = {}

    def plain(stem: int) -> NDArray[np.float64]:
        """Path lengths (V,) from ``stem``'s foot over its 1 m neighbourhood (inf elsewhere)."""
        if stem not in distances:
            xy = stems_xy_m[stem]
            local = np.sort(np.asarray(tree.query_ball_point(xy, reach_m), dtype=np.intp))
            sources = _sources(graph.centres_m[local], xy, seed_radius_m, seed_height_m)
            d = np.full(voxels, np.inf)
            if len(sources):
                position = np.full(voxels, -1, dtype=np.intp)
                position[local] = np.arange(len(local))
                sub = _subgraph(graph.edges, local, position)
                d[local] = dijkstra(sub, directed=False, indices=sources, min_only=True)
            distances[stem] = d
        return distances[stem]

    found: list[tuple[float, int, int]] = []  # (share on the way, stem, the other stem)
    for stem in range(stems):
        mine = np.flatnonzero(owner == stem)
        seconds = runner_up[mine]
        seconds = seconds[seconds >= 0]
        if len(seconds) == 0:
            continue
        other = int(np.bincount(seconds).argmax())
        off = claims is not None and (
            bool(claims.off[stem])
            # one plant's place: the smaller of the two is held as off the grid
            or (claims.node[stem] >= 0 and claims.node[stem] == claims.node[other])
        )
        if size[stem] > (1.0 if off else LEAF_END_SIZE) * size[other]:
            continue
        standing = graph.centres_m[mine, 2] > feet_m[stem, 2] + LYING_M
        bar = share_off_grid if off else share
        on_the_way = _share_on_the_way(
            plain, stem, mine, np.full(len(mine), other), standing, slack_m
        )
        if on_the_way < bar and claims is not None and claims.off[stem]:
            # at no node: its voxels may lie on the ways to two plants (two leaves come down
            # crossing), each voxel weighed against the stem that reaches it second
            each = np.where(runner_up[mine] >= 0, runner_up[mine], other)
            on_the_way = max(
                on_the_way, _share_on_the_way(plain, stem, mine, each, standing, slack_m)
            )
        if on_the_way >= bar:
            found.append((on_the_way, stem, other))

    def root(stem: int) -> int:
        while into[stem] != stem:
            stem = int(into[stem])
        return stem

    for _, stem, other in sorted(found, reverse=True):  # the most leaf-like first
        if root(other) != stem:
            into[stem] = root(other)
    return np.array([root(stem) for stem in range(stems)], dtype=np.intp)


def _share_on_the_way(
    plain: Callable[[int], NDArray[np.float64]],
    stem: int,
    mine: NDArray[np.intp],
    seconds: NDArray[np.intp],
    standing: NDArray[np.bool_],
    slack_m: float,
) -> float:
    """The share of ``stem``'s ``standing`` voxels (of ``mine``) that lie on the way between its
    foot and the foot of their stem in ``seconds``: the two feet's plain path lengths to the
    voxel (``plain(stem)``, (V,)) at most ``slack_m`` more than the shortest way between those
    two feet (the least such sum over ``mine``)."""
    on = np.zeros(len(mine), dtype=bool)
    valid = np.zeros(len(mine), dtype=bool)
    own = plain(stem)[mine]
    for second in np.unique(seconds):
        these = seconds == second
        total = own + plain(int(second))[mine]
        finite = np.isfinite(total)
        way = total[finite].min(initial=np.inf)
        valid[these] = finite[these]
        on[these] = total[these] <= way + slack_m
    weighed = standing & valid
    return float(np.mean(on[weighed])) if weighed.any() else 0.0


def _shared(
    graph: VoxelGraph, tree: cKDTree, stems_xy_m: NDArray[np.float64], seed_radius_m: float
) -> NDArray[np.bool_]:
    """(V,) the voxels of the graph's connected parts that hold two stems' feet or more: only
    there can two plants' paths meet (on a seedling plot, where no canopies touch, nowhere).
    ``tree``: the plan-view tree of the graph's voxel centres."""
    _, label = connected_components(graph.edges, directed=False)
    feet = tree.query_ball_point(np.asarray(stems_xy_m).reshape(-1, 2), seed_radius_m)
    parts = [np.unique(label[np.asarray(f, dtype=np.intp)]) for f in feet]
    stems_per_part = np.bincount(
        np.concatenate([*parts, np.empty(0, dtype=np.intp)]).astype(np.intp),
        minlength=int(label.max()) + 1,
    )
    return stems_per_part[label] >= 2  # type: ignore[no-any-return]


def _subgraph(edges: csr_matrix, local: NDArray[np.intp], position: NDArray[np.intp]) -> csr_matrix:
    """The edges among the ``local`` voxels, renumbered by ``position`` (global -> local, -1
    elsewhere), in time proportional to their edges, not to the whole graph."""
    rows = edges[local]
    columns = position[rows.indices]
    keep = columns >= 0
    row_ids = np.repeat(np.arange(len(local)), np.diff(rows.indptr))
    n = len(local)
    return coo_matrix((rows.data[keep], (row_ids[keep], columns[keep])), shape=(n, n)).tocsr()


def _near(
    centres_m: NDArray[np.float64], stem_xy: NDArray[np.float64], radius_m: float
) -> NDArray[np.bool_]:
    """(V,) whether each of ``centres_m`` lies within ``radius_m`` of the stem (plan view)."""
    return np.sum((centres_m[:, :2] - stem_xy) ** 2, axis=1) <= radius_m**2  # type: ignore[no-any-return]


def _free_collar(
    edges: csr_matrix,
    bend: csr_matrix,
    centres_m: NDArray[np.float64],
    stem_xy: NDArray[np.float64],
    radius_m: float,
    top_m: float,
) -> csr_matrix:
    """``edges`` without their ``bend`` part (laid out as ``edges``) on the steps that stay
    within ``radius_m`` (plan view) of this path's own stem and below ``top_m``: its collar."""
    inside = _near(centres_m, stem_xy, radius_m) & (centres_m[:, 2] <= top_m)
    rows = np.repeat(np.arange(edges.shape[0]), np.diff(edges.indptr))
    free = inside[rows] & inside[edges.indices]
    out = edges.copy()
    out.data = edges.data - np.where(free, bend.data, 0.0)
    return out


def _across_junctions(
    edges: csr_matrix,
    centres_m: NDArray[np.float64],
    stem_xy: NDArray[np.float64],
    junctions: Junctions,
    longest_m: float,
) -> csr_matrix:
    """``edges`` (between the states at ``centres_m``) with the steps across the gaps near
    this path's own stem (:class:`Junctions`) added both ways; the graph's own steps are at
    most ``longest_m``, so no step is added twice."""
    near = np.flatnonzero(_near(centres_m, stem_xy, junctions.radius_m))
    if len(near) < 2:
        return edges
    pairs = cKDTree(centres_m[near]).query_pairs(junctions.gap_m, output_type="ndarray")
    a, b = near[pairs[:, 0]], near[pairs[:, 1]]
    length = np.linalg.norm(centres_m[a] - centres_m[b], axis=1)
    gap = length > longest_m
    if not gap.any():
        return edges
    a, b, cost = a[gap], b[gap], length[gap] + junctions.penalty_m
    steps = coo_matrix(
        (np.concatenate([cost, cost]), (np.concatenate([a, b]), np.concatenate([b, a]))),
        shape=edges.shape,
    )
    return (edges + steps).tocsr()


def _outward(
    edges: csr_matrix,
    centres_m: NDArray[np.float64],
    stem_xy: NDArray[np.float64],
    penalty: float,
    column_m: float = 0.0,
) -> csr_matrix:
    """``edges`` made directed: the step u -> v costs its length plus ``penalty`` times how much
    nearer to the stem (plan view) v is than u. A plant grows outwards from its stem: a leaf
    reached from a neighbour's stem across a contact and followed back towards that stem pays
    for every centimetre, the same leaf reached along itself from its own stem does not.

    Within ``column_m`` of the stem (its own column, where its sources are) no step is inward:
    there "towards the stem" means nothing, and a path climbing the stem zig-zags between
    voxel centroids a few millimetres either side of it. At 10 x those sideways steps cost a
    seedling's stem so much that a tall neighbour's leaf touching it took its leaf, and the
    seedling was merged as a leaf's end (`test_a_seedling_touching_a_tall_plant_is_a_plant`)."""
    if penalty <= 0.0:
        return edges
    radius = np.maximum(np.hypot(*(centres_m[:, :2] - stem_xy).T), column_m)
    rows = np.repeat(np.arange(edges.shape[0]), np.diff(edges.indptr))
    inward = np.maximum(radius[rows] - radius[edges.indices], 0.0)
    out = edges.copy()
    out.data = edges.data + penalty * inward
    return out


def _sources(
    centres_m: NDArray[np.float64], xy: NDArray[np.float64], radius_m: float, height_m: float
) -> NDArray[np.intp]:
    """Indices (into ``centres_m``) of the voxels at the stem's foot."""
    near = np.flatnonzero(_near(centres_m, xy, radius_m))
    if len(near) == 0:
        return near
    z = centres_m[near, 2]
    return near[z <= z.min() + height_m]  # type: ignore[no-any-return]
