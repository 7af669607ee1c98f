"""The planting grid as a prior: where plants should stand, in the reconstruction's frame.

The user gives the grid in the map frame (``plan.planting_grid`` of the session, see the
session-format spec): ``rows`` x ``columns`` nodes, plants ``plant_spacing_m`` apart along a
row (direction ``row_direction_deg`` from the map's x axis, counter-clockwise), rows
``row_spacing_m`` apart to its left, row 1 column 1 at ``origin``. :func:`grid_nodes` puts the
nodes into the field frame. The grid is then fitted to the stems found
(:func:`fitted_to_stems`): the map frame is only as good as the base's localisation, and a base
a decimetre off would put the nodes beside their plants. The prior never forces a plant: a node
with no stem is searched again with a weaker stem test (:func:`stems_at_empty_nodes`) and
otherwise reported missing; a plant at no node is kept and reported extra.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, fit_plan_motion, rotation_angle_deg, transform_points
from fieldapp.io.planting import PlantingGrid
from fieldapp.recon.settings import GridPrior, StemSettings
from fieldapp.recon.stems import Stem, local_ground_z_m, stem_columns

DEFAULT_SNAP_RADIUS_M = 0.15
FIT_MIN_STEMS = 3
"""Stems at distinct nodes a fit of the grid rests on (a turn and a shift: three unknowns)."""
FIT_REACH_SHARE = 0.45
"""How far from a node (a share of the nodes' spacing) a stem may stand to be paired with it
while the grid is fitted: under half the spacing, so a stem pairs with its own node when the
grid is off by less than half a spacing (40 cm on the 80 cm grid), never with the next."""
FIT_ROUNDS = 20
TRUSTED_SHARE = 0.5
"""A grid is a prior on where plants stand only when this share of its nodes or more have a
stem at them (:func:`node_claims`); a field's gaps leave 5-20 % of them empty."""
FIT_MIN_MOVE_SHARE = 1 / 3
"""A fit moving no node farther than this share of the snap radius (5 cm of 15) is not
applied: the grid stands on its plants as well as plants stand on their nodes, and moving it
would only chase their scatter (and change the weak-stem search at empty nodes)."""


@dataclass(frozen=True)
class GridNodes:
    """Grid nodes in the field frame: ``xy_m`` (M, 2), their 1-based ``row`` and ``column``
    (M,), and how far from its node a plant's base may stand (``snap_radius_m``)."""

    xy_m: NDArray[np.float64]
    row: NDArray[np.intp]
    column: NDArray[np.intp]
    snap_radius_m: float = DEFAULT_SNAP_RADIUS_M


def grid_nodes(
    rows: int,
    columns: int,
    row_spacing_m: float,
    plant_spacing_m: float,
    origin_xy_m: tuple[float, float],
    row_direction_deg: float,
    T_field_map: Matrix4,
    snap_radius_m: float = DEFAULT_SNAP_RADIUS_M,
) -> GridNodes:
    """The nodes of a grid given in the map frame, expressed in the field frame."""
    angle = np.radians(row_direction_deg)
    along = np.array([np.cos(angle), np.sin(angle)])
    across = np.array([-np.sin(angle), np.cos(angle)])
    row, column = np.mgrid[0:rows, 0:columns]
    row, column = row.ravel(), column.ravel()
    xy_map = (
        np.asarray(origin_xy_m, dtype=np.float64)
        + column[:, None] * plant_spacing_m * along
        + row[:, None] * row_spacing_m * across
    )
    xy_field = xy_map @ T_field_map[:2, :2].T + T_field_map[:2, 3]
    return GridNodes(
        xy_field, (row + 1).astype(np.intp), (column + 1).astype(np.intp), snap_radius_m
    )


@dataclass(frozen=True)
class GridFit:
    """How :func:`fitted_to_stems` fitted the grid: the stems (at distinct nodes) the fit rests
    on, how far it moves the node that moves most, how far it turns, and whether it was
    applied (``moved_m`` beyond :data:`FIT_MIN_MOVE_SHARE` of the snap radius)."""

    stems: int
    moved_m: float
    turned_deg: float
    applied: bool


def fitted_to_stems(
    grid: GridNodes, stems_xy_m: NDArray[np.float64]
) -> tuple[GridNodes, GridFit | None]:
    """The grid turned and shifted (plan view, least squares) onto the stems ``stems_xy_m``
    (S, 2) standing near its nodes, and the fit; the grid unchanged (and ``None``) when
    fewer than :data:`FIT_MIN_STEMS` stems pair with nodes or the fit would leave fewer
    stems within the snap radius of a node than before; unchanged (the fit not applied) when
    it would move no node farther than :data:`FIT_MIN_MOVE_SHARE` of the snap radius.

    Stems pair with the nearest node within :data:`FIT_REACH_SHARE` of the spacing (one stem
    a node, the nearest), the grid is fitted to them and the pairs are taken again until they
    hold; then again within the snap radius only, so a stem standing off the grid (a weed, a
    plant sown astray) does not pull it."""
    if len(stems_xy_m) < FIT_MIN_STEMS or len(grid.xy_m) < 2:
        return grid, None
    spacing = float(cKDTree(grid.xy_m).query(grid.xy_m, k=2)[0][:, 1].min())
    T = np.eye(4)
    for reach in (FIT_REACH_SHARE * spacing, grid.snap_radius_m):
        pairs: tuple[int, ...] = ()
        for _ in range(FIT_ROUNDS):
            nodes, stems = _paired(_moved(T, grid.xy_m), stems_xy_m, reach)
            if len(nodes) < FIT_MIN_STEMS:
                return grid, None
            if tuple(nodes) + tuple(stems) == pairs:
                break
            pairs = tuple(nodes) + tuple(stems)
            T = fit_plan_motion(grid.xy_m[nodes], stems_xy_m[stems])
    moved = _moved(T, grid.xy_m)
    before = len(_paired(grid.xy_m, stems_xy_m, grid.snap_radius_m)[0])
    after = len(_paired(moved, stems_xy_m, grid.snap_radius_m)[0])
    if after < max(before, FIT_MIN_STEMS):
        return grid, None
    moved_m = float(np.linalg.norm(moved - grid.xy_m, axis=1).max())
    applied = moved_m > FIT_MIN_MOVE_SHARE * grid.snap_radius_m
    fit = GridFit(after, moved_m, rotation_angle_deg(T[:3, :3]), applied)
    return (replace(grid, xy_m=moved) if applied else grid), fit


def at_nodes(
    grid: GridNodes, xy_m: NDArray[np.float64]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(node, index) pairs of the positions ``xy_m`` (K, 2) standing at a node: each with its
    nearest node within the snap radius, one a node (the nearest); the rule plants are placed
    on the grid by, and stems judged off it."""
    if len(xy_m) == 0:
        return np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp)
    return _paired(grid.xy_m, xy_m, grid.snap_radius_m)


@dataclass(frozen=True)
class NodeClaims:
    """Where stems stand on a planting grid: ``node`` (S,) each stem's nearest node within the
    snap radius (-1: none), and ``off`` (S,) the stems at no node (:func:`at_nodes`: not the
    nearest stem of any). Two stems of one ``node`` are two claims on one plant's place."""

    node: NDArray[np.intp]
    off: NDArray[np.bool_]


def node_claims(grid: GridNodes, stems_xy_m: NDArray[np.float64]) -> NodeClaims | None:
    """Where the stems ``stems_xy_m`` (S, 2) stand on ``grid``. ``None`` when fewer than
    :data:`TRUSTED_SHARE` of the nodes have a stem: a grid that far from the stems (a plan for
    another plot, a base lost beyond what the fit mends) says nothing about where plants
    are."""
    if len(stems_xy_m) == 0 or len(grid.xy_m) == 0:
        return None
    distance, node = _nearest(grid.xy_m, stems_xy_m, grid.snap_radius_m)
    nodes, stems = _first_claims(distance, node)
    if len(nodes) < TRUSTED_SHARE * len(grid.xy_m):
        return None
    off = np.ones(len(stems_xy_m), dtype=bool)
    off[stems] = False
    return NodeClaims(node, off)


def _moved(T: Matrix4, xy_m: NDArray[np.float64]) -> NDArray[np.float64]:
    return transform_points(T, np.column_stack([xy_m, np.zeros(len(xy_m))]))[:, :2]


def _paired(
    nodes_xy_m: NDArray[np.float64], stems_xy_m: NDArray[np.float64], reach_m: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(node, stem) index pairs: each stem with its nearest node within ``reach_m``, one stem a
    node (the nearest), in node order."""
    return _first_claims(*_nearest(nodes_xy_m, stems_xy_m, reach_m))


def _nearest(
    nodes_xy_m: NDArray[np.float64], stems_xy_m: NDArray[np.float64], reach_m: float
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """(S,) each stem's distance to its nearest node within ``reach_m`` (inf: none) and that
    node (-1: none)."""
    distance, node = cKDTree(nodes_xy_m).query(stems_xy_m, distance_upper_bound=reach_m)
    return distance, np.where(np.isfinite(distance), node, -1).astype(np.intp)


def _first_claims(
    distance: NDArray[np.float64], node: NDArray[np.intp]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(node, stem) pairs of :func:`_nearest`'s answer: one stem a node, the nearest, in node
    order."""
    stems = np.flatnonzero(node >= 0)
    order = stems[np.lexsort((distance[stems], node[stems]))]
    first = np.ones(len(order), dtype=bool)
    first[1:] = node[order][1:] != node[order][:-1]
    kept = order[first]
    return node[kept], kept.astype(np.intp)


def plan_nodes(grid: PlantingGrid, T_field_map: Matrix4) -> GridNodes:
    """The nodes of a plan's planting grid (map frame, ``session-format.md``) in the field
    frame."""
    return grid_nodes(
        grid.rows,
        grid.columns,
        grid.row_spacing_m,
        grid.plant_spacing_m,
        (grid.origin.x, grid.origin.y),
        grid.row_direction_deg,
        T_field_map,
    )


def prior_nodes(grid: GridPrior) -> GridNodes:
    """The nodes of the settings' grid (``plants.grid``: axis-aligned, in the output frame)."""
    return grid_nodes(
        grid.rows,
        grid.columns,
        grid.row_spacing_m,
        grid.column_spacing_m,
        (grid.origin_x_m, grid.origin_y_m),
        0.0,
        np.eye(4),
        grid.snap_radius_m,
    )


def stems_at_empty_nodes(
    points_m: NDArray[np.float64],
    soil_m: NDArray[np.float64],
    stems: list[Stem],
    grid: GridNodes,
    settings: StemSettings,
    soil_tree: cKDTree | None = None,
) -> list[Stem]:
    """Stems found with the weaker test (``prior_layer_fraction``) at nodes that have none,
    where the column may start up to ``search_height_m - band_m`` above the soil (its band
    raised by ``max_foot_gap_m`` at a time): a plant at a plot's edge, seen only from inside
    the plot, or whose foot the neighbours' lower leaves hide, shows its stem from 10 cm up
    (an independent renderer's 80 cm grid: one such plant of 33, 86 cm tall, was taken whole
    by its neighbour along their touching leaves). ``soil_tree``: the plan-view tree over
    ``soil_m[:, :2]`` when the caller has one."""
    weak = settings.model_copy(update={"min_layer_fraction": settings.prior_layer_fraction})
    # the foot may be hidden (a plot's edge, the neighbours' lower leaves): the band is raised
    # a step at a time, up to where a stem is still looked for
    step = max(settings.max_foot_gap_m, settings.cell_m)
    raises = np.arange(0.0, max(settings.search_height_m - settings.band_m, 0.0) + 1e-9, step)
    found: list[Stem] = []
    if len(points_m) == 0:
        return found
    tree = cKDTree(points_m[:, :2])
    if soil_tree is None and len(soil_m):  # once: a node asks twice
        soil_tree = cKDTree(soil_m[:, :2])
    for xy in grid.xy_m:
        if any(np.linalg.norm(stem.xy_m - xy) <= grid.snap_radius_m for stem in stems):
            continue
        near = np.asarray(tree.query_ball_point(xy, grid.snap_radius_m), dtype=np.intp)
        local = points_m[near]
        if len(local) == 0:
            continue
        heights = local[:, 2] - local_ground_z_m(soil_m, local[:, :2], soil_tree=soil_tree)
        for raised in raises:
            origin, cells, fractions = stem_columns(local, heights - raised, weak)
            if len(cells):
                break
        if len(cells) == 0:
            continue
        best = int(np.argmax(fractions))
        stem_xy = origin + (cells[best] + 0.5) * settings.cell_m
        ground = float(local_ground_z_m(soil_m, stem_xy[None], soil_tree=soil_tree)[0])
        found.append(Stem(stem_xy, ground, float(fractions[best])))
    return found


def apply_grid_prior_nodes(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    grid: GridNodes,
    base_height_m: float,
    merges: list[str],
) -> NDArray[np.intp]:
    """Density clusters split by the nodes their low points stand at, and clusters standing at
    one node joined (listed in ``merges``); for clouds where no stem is seen.

    A cluster claims a node when some of its points lower than ``base_height_m`` above the
    lowest point lie within the snap radius of the node. A cluster claiming several nodes is
    split by the nearest node; clusters claiming no node are left alone.
    """
    if len(points_m) == 0:
        return labels.copy()
    distance, nearest = cKDTree(grid.xy_m).query(points_m[:, :2])
    low = points_m[:, 2] <= points_m[:, 2].min() + base_height_m
    claims = (labels >= 0) & low & (distance <= grid.snap_radius_m)
    pairs = np.unique(np.stack([labels[claims], nearest[claims]], axis=1), axis=0)
    out = labels.copy()
    if len(pairs) == 0:
        return out
    base = int(labels.max()) + 1
    claimed_by = {int(label): pairs[pairs[:, 0] == label, 1] for label in np.unique(pairs[:, 0])}
    node_owners: dict[int, list[int]] = {}
    for label, nodes in claimed_by.items():
        for node in nodes:
            node_owners.setdefault(int(node), []).append(label)
        members = np.flatnonzero(labels == label) if len(nodes) > 1 else None
        if members is None:
            out[labels == label] = base + int(nodes[0])
            continue
        to_nodes = np.linalg.norm(points_m[members, None, :2] - grid.xy_m[nodes][None], axis=2)
        out[members] = base + nodes[np.argmin(to_nodes, axis=1)]
    for node, owners in sorted(node_owners.items()):
        if len(owners) > 1:
            merges.append(f"{len(owners)} clusters joined at grid node {node}")
    return out
