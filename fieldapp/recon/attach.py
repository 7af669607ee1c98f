"""Doubtful points joined to the plants they touch, once the plants are found without them.

The statistical filter removes a point whose neighbours lie far on average
(:func:`fieldapp.recon.filters.sor_limit`); a leaf's thin tip, sparse and often seen by one
station, is such a point as much as a flying pixel is. With the filter's floor raised to keep
the tips, the widths of this project's touching plots came nearer the truth on every plot, but
on an independent renderer's the same points bridged touching leaves and two plants lost whole
parts to their neighbours (RECONSTRUCTION.md, "Doubtful points"). So the points kept only by
the raised floor (:func:`fieldapp.recon.filters.split_outliers`) take no part in finding the
plants; each then takes the plant it reaches first, stepping from point to point within
``reach_m``, and is dropped where it reaches none: a tip grows on from its own leaf's points,
and a stray veil of flying pixels that touches no plant is left out as before.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

ATTACH_REACH_M = 0.01
"""How far a doubtful point may be from the point it joins through: the radius filter's
8 mm, with room for the 2 mm voxels the fused cloud is averaged in. Farther, a tip's points
would reach across the gap between two leaves."""
ATTACH_GAP_M = 0.08
"""How far a group of doubtful points that reaches no plant point by point may lie from the
plant it joins: a tip's sparse end lies beyond the stretch of it the filter removed
outright, 2-5 cm on from its leaf's kept points on this project's touching plot seed 3
(median 2.9 cm), 5.8-6.5 cm at the drooping tips that set the widths of an independent
renderer's touching plants (2026-12-06, session 36; 5 cm until then). At 8 cm: the widths of
three of that renderer's four touching plots 1.75 / 2.39 / 1.66 -> 1.62 / 1.66 / 0.76 cm, and
the same to the digit on 38 inputs of this project's two plant models, leaning plants and
the fourth renderer (its touching 3 2.11 -> 2.10).
The margin below is what keeps a group between two plants out; a group near the soil
keeps :data:`ATTACH_GROUND_GAP_M`."""
ATTACH_GROUND_GAP_M = 0.05
"""The gap for a group of doubtful points with a point near the soil, or not green, or on a
plot without colour: there a group may be a clod or the soil beside a leaf, not a tip (a
depth-only plot with 40 clods a square metre: at 8 cm clods joined four plants, width RMSE
0.87 -> 2.12 cm). A piece of the cloud too small to be a plant crosses no gap there
(``plants._with_loose``): it may be a weed."""
ATTACH_MARGIN_M = 0.01
"""A group joins the plant nearest it only where every other plant's points lie at least this
much farther: nearer, which of two touching plants a sparse pair belongs to is a guess (the
second plant model's touching seed 3: a pair 3.9 cm from one plant and 4.7 cm from its
neighbour made the first 2.2 cm wider), and the group is dropped."""


MAX_GRID_CELLS = 1 << 26
"""The largest grid :func:`_near` builds (64 MB): a 9 x 9 station plot needs about a third;
beyond, every labelled point goes into the joins' tree (the same joins, slower)."""


def attach_doubtful(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    doubtful_m: NDArray[np.float64],
    reach_m: float = ATTACH_REACH_M,
    gap_m: float = ATTACH_GAP_M,
    margin_m: float = ATTACH_MARGIN_M,
    gaps_m: NDArray[np.float64] | None = None,
) -> NDArray[np.intp]:
    """(D,) the label each of ``doubtful_m`` (D, 3) takes: that of the labelled point of
    ``points_m`` (N, 3), ``labels`` (N,) (-1: in no plant), it reaches along the shortest
    path of steps of at most ``reach_m`` through doubtful points; for a group of doubtful
    points (steps of at most ``reach_m``) that reaches none so, that of the labelled point
    nearest the group, within ``gap_m``, where every other label's points lie ``margin_m``
    farther; -1 for the rest. ``gaps_m``: (D,) the widest gap each point lets its group cross
    (at most ``gap_m``; a group crosses the narrowest of its points'), where they differ."""
    if gaps_m is not None:  # no search farther than the widest gap any point allows
        gap_m = min(gap_m, float(gaps_m.max(initial=0.0)))
    d = len(doubtful_m)
    found = np.full(d, -1, dtype=np.intp)
    if d == 0:
        return found
    # only the labelled points near a doubtful one can be reached: a tree of those alone (a
    # plot's cloud is 2 000 times its doubtful points, and a tree of it cost 0.2 s)
    labelled = np.flatnonzero((labels >= 0) & _near(points_m, doubtful_m, max(reach_m, gap_m)))
    if len(labelled) == 0:
        return found
    # built for speed, not for balance: a few queries each (the same answers either way)
    doubtful_tree = cKDTree(doubtful_m, balanced_tree=False, compact_nodes=False)
    labelled_tree = cKDTree(points_m[labelled], balanced_tree=False, compact_nodes=False)
    among = doubtful_tree.sparse_distance_matrix(doubtful_tree, reach_m, output_type="coo_matrix")
    # the labelled points a doubtful point reaches directly: the paths' sources
    to_labelled = doubtful_tree.sparse_distance_matrix(
        labelled_tree, reach_m, output_type="coo_matrix"
    )
    if to_labelled.nnz:
        found = _along_paths(among, to_labelled, d, labels[labelled])
    lonely = found < 0
    alone = np.flatnonzero(lonely)
    if len(alone) == 0 or gap_m <= 0.0:
        return found
    # the groups that reached no plant: each joins the labelled point nearest any of its own
    keep = lonely[among.row] & lonely[among.col]
    inside = coo_matrix(
        (np.ones(int(keep.sum())), (among.row[keep], among.col[keep])), shape=(d, d)
    )
    group = connected_components(inside, directed=False)[1][alone]
    alone_m = doubtful_m[alone]
    nearest = _Nearest.of(points_m[labelled], labels[labelled], alone_m, gap_m)
    distance = nearest.first_m
    order = np.lexsort((distance, group))  # by group, nearest first
    starts = np.flatnonzero(np.r_[True, np.diff(group[order]) != 0])
    for members in np.split(order, starts[1:]):
        index = members[0]  # the group's point nearest a plant
        if not np.isfinite(distance[index]):
            continue
        if gaps_m is not None and distance[index] > gaps_m[alone[members]].min():
            continue
        label = nearest.first[index]
        if nearest.besides(label, members) >= distance[index] + margin_m:
            found[alone[members]] = label
    return found


@dataclass(frozen=True)
class _Nearest:
    """For each of a set of points, its nearest plant and that plant's distance, and the
    distance of the nearest point of any other plant (infinite beyond the search's reach).

    Each plant's tree is asked once for all the points, which gives the nearest plant too: a
    list of every plant point within the gap of each point took the plants step to 3.25 GB
    and 24 s of CPU on an independent renderer's touching plot (20 000 lonely doubtful points,
    each with thousands of leaf points within 8 cm)."""

    first_m: NDArray[np.float64]
    first: NDArray[np.intp]
    second_m: NDArray[np.float64]

    @classmethod
    def of(
        cls,
        points_m: NDArray[np.float64],
        labels: NDArray[np.intp],
        around_m: NDArray[np.float64],
        reach_m: float,
    ) -> _Nearest:
        """Of each of ``around_m`` (A, 3), among ``points_m`` (N, 3) labelled ``labels``
        (N,) within ``reach_m``."""
        first_m = np.full(len(around_m), np.inf)
        second_m = np.full(len(around_m), np.inf)
        first = np.full(len(around_m), -1, dtype=np.intp)
        bound = float(np.nextafter(reach_m, np.inf))  # within reach, as a ball query is
        order = np.argsort(labels, kind="stable")
        plants, starts = np.unique(labels[order], return_index=True)
        for plant, members in zip(plants, np.split(order, starts[1:]), strict=True):
            tree = cKDTree(points_m[members], balanced_tree=False, compact_nodes=False)
            gap_m = tree.query(around_m, distance_upper_bound=bound)[0]
            nearer = gap_m < first_m
            second_m = np.where(nearer, first_m, np.minimum(second_m, gap_m))
            first_m = np.where(nearer, gap_m, first_m)
            first = np.where(nearer, plant, first)
        return cls(first_m, first, second_m)

    def besides(self, label: int, members: NDArray[np.intp]) -> float:
        """The distance from the ``members`` (indices into the points) to the nearest point
        of a plant other than ``label``; infinite where there is none within reach."""
        other = np.where(
            self.first[members] != label, self.first_m[members], self.second_m[members]
        )
        return float(other.min(initial=np.inf))


def _near(
    points_m: NDArray[np.float64], around_m: NDArray[np.float64], distance_m: float
) -> NDArray[np.bool_]:
    """(N,) which of ``points_m`` (N, 3) may lie within ``distance_m`` of one of
    ``around_m`` (M, 3): those in the cells of half ``distance_m`` within two cells of one of
    theirs (every point within the distance, and some beyond), looked up in a grid over
    ``around_m`` alone."""
    cell_m = distance_m / 2
    low = around_m.min(axis=0) - 2.5 * cell_m  # every cell of theirs two or more in
    cells = np.floor((around_m - low) / cell_m).astype(np.intp)
    shape = cells.max(axis=0) + 3
    if np.prod(shape.astype(np.float64)) > MAX_GRID_CELLS:  # a field, not a plot: no grid
        return np.ones(len(points_m), dtype=bool)
    grid = np.zeros(shape, dtype=bool)
    for di, dj, dk in itertools.product(range(-2, 3), repeat=3):
        grid[cells[:, 0] + di, cells[:, 1] + dj, cells[:, 2] + dk] = True
    ijk = np.floor((points_m - low) / cell_m).astype(np.intp)
    inside = np.flatnonzero(((ijk >= 0) & (ijk < shape)).all(axis=1))
    near = np.zeros(len(points_m), dtype=bool)
    near[inside] = grid[ijk[inside, 0], ijk[inside, 1], ijk[inside, 2]]
    return near


def _along_paths(
    among: coo_matrix, to_labelled: coo_matrix, d: int, source_labels: NDArray[np.intp]
) -> NDArray[np.intp]:
    """(D,) the label of the labelled point (of labels ``source_labels``) each of ``d``
    doubtful points reaches first through the steps ``among`` them (D, D) from the steps
    ``to_labelled`` (D, L); -1 where none."""
    sources, source_node = np.unique(to_labelled.col, return_inverse=True)
    # nodes: the doubtful points, then the sources; a source's edges lead to doubtful points
    # only, so no path passes through a labelled point
    rows = np.concatenate([among.row, to_labelled.row])
    columns = np.concatenate([among.col, d + source_node])
    lengths = np.concatenate([among.data, to_labelled.data])
    # a zero length (two points in one place) is no edge to scipy: the least step instead
    lengths = np.maximum(lengths, np.finfo(np.float64).tiny)
    nodes = d + len(sources)
    graph = coo_matrix((lengths, (rows, columns)), shape=(nodes, nodes)).tocsr()
    _, _, reached_from = dijkstra(
        graph,
        directed=False,
        indices=d + np.arange(len(sources)),
        min_only=True,
        return_predecessors=True,
    )
    found = np.full(d, -1, dtype=np.intp)
    from_source = reached_from[:d]
    reached = from_source >= 0
    found[reached] = source_labels[sources[from_source[reached] - d]]
    return found
