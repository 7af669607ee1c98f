"""Plants: found from their stems, density clusters where no stem is seen, stable ids.

:func:`search_plants` finds the stem feet (:mod:`fieldapp.recon.stems`), gives every point to
the stem it is nearest to along the plant (:mod:`fieldapp.recon.geodesic`), clusters what no
stem reaches by connected components of occupied voxels (26-neighbourhood: two points are in
one cluster when a chain of occupied voxels joins them; DBSCAN with eps of about one voxel and
min_samples 1, an order of magnitude faster, PERFORMANCE-NOTES.md), measures each plant, places
it on the planting grid when there is one (:mod:`fieldapp.recon.grid`) and numbers the plants
in reading order.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fieldapp.recon.attach import ATTACH_GAP_M, ATTACH_GROUND_GAP_M, attach_doubtful
from fieldapp.recon.cloud import Cloud, width_points
from fieldapp.recon.exg import NOT_GREEN_EXG, excess_green, grey_group, not_green_group
from fieldapp.recon.filters import not_green
from fieldapp.recon.geodesic import (
    UNREACHED,
    Assignment,
    Junctions,
    StateGraph,
    VoxelGraph,
    assign_to_stems,
    leaf_ends,
    state_graph,
    voxel_graph,
    voxel_neighbours,
)
from fieldapp.recon.grid import (
    GridFit,
    GridNodes,
    NodeClaims,
    apply_grid_prior_nodes,
    at_nodes,
    fitted_to_stems,
    node_claims,
    prior_nodes,
    stems_at_empty_nodes,
)
from fieldapp.recon.ribbons import follow_leaves
from fieldapp.recon.settings import GridPrior, PlantSettings, StemSettings
from fieldapp.recon.stems import Stem, find_stems, local_ground_z_m, merged_into
from fieldapp.recon.traits import PlantTraits, base_xy_m, measure_plant

WIDEST_M = 0.01
"""A plant's widest extent: its points within this of the circle that encloses it (plan
view), the points its width is measured between."""
MEETS_NOTE = "may be wider or narrower than measured: its widest extent meets plant"
MEETS_WARNING = "may be wider or narrower than measured, their widest extent meets another plant"
"""How a plant whose widest extent meets another (:func:`widest_meets`) is cautioned in its
report entry (with the other's id) and in the warnings. Either way: its leaf may go on into
the other plant, or what makes it widest may be the other's (over the touching bench's 45
plots, the plants so named that were more than 3 cm off: 12 too narrow, 11 too wide)."""

JOINED_SHARE = 0.05
"""A plant more than this share of whose points no stem reached along the plant, joined to it
as the nearest plant of a density cluster it shares with another (:func:`_join_fragments`),
has them counted as ambiguous, so that it is flagged: so much of a plant cut from its stem
may be a neighbour's leaves or the whole of a neighbour. On this simulator's 15 bench plots
no plant had more than 0.4 % so joined, nor on an independent renderer's touching plots with
the plan's crop; with a crop cut short there (stations 0.8 m apart) four plants had 20-38 %,
one of them the body of its neighbour, which was left a 30 cm stump, and neither was
flagged."""

NOISE = -1
FRAGMENT = -2
"""A point of a group no stem reaches that is too small to be a plant (under ``min_points``):
a leaf's tip or a piece of leaf the outlier filters left apart from the rest of it. It joins
the plant it reaches as a doubtful point does (:func:`_with_loose`), or is left out as noise."""


def assign_by_settings(
    points_m: NDArray[np.float64],
    stems_xy_m: NDArray[np.float64],
    s: StemSettings,
    graph: VoxelGraph | None = None,
    states: StateGraph | None = None,
    junctions: bool = True,
) -> Assignment:
    """Every point of ``points_m`` (N, 3) to the stem at ``stems_xy_m`` (S, 2) it is nearest to
    along the plant (:func:`fieldapp.recon.geodesic.assign_to_stems` over a voxel graph, or
    ``graph``, the points' when the caller has built it, and ``states``, its
    :func:`stem_states`), with the stem settings ``s``: one place for the reconstruction and
    manual splits alike. ``junctions``: with the steps across the gaps near each stem
    (``s.junction_radius_m``)."""
    graph = voxel_graph(points_m, s.graph_voxel_m) if graph is None else graph
    steps = None
    if junctions and s.junction_radius_m > 0.0:
        steps = Junctions(s.junction_radius_m, s.junction_gap_m, s.junction_penalty_m)
    return assign_to_stems(
        graph,
        stems_xy_m,
        s.seed_radius_m,
        s.seed_height_m,
        s.reach_m,
        s.ambiguity_margin_m,
        s.inward_penalty,
        s.bend_penalty_m,
        s.sheet_aware,
        s.collar_radius_m,
        s.collar_height_m,
        steps,
        stem_states(graph, stems_xy_m, s) if states is None else states,
    )


def stem_states(graph: VoxelGraph, stems_xy_m: NDArray[np.float64], s: StemSettings) -> StateGraph:
    """The costs the assignment of ``graph``'s voxels to the stems at ``stems_xy_m`` searches
    over (:func:`fieldapp.recon.geodesic.state_graph`), with the stem settings ``s``."""
    return state_graph(
        graph,
        stems_xy_m,
        s.seed_radius_m,
        s.bend_penalty_m,
        s.sheet_aware,
        keep_bend=s.collar_radius_m > 0.0,
    )


def voxel_components(points_m: NDArray[np.float64], voxel_m: float) -> NDArray[np.intp]:
    """(N,) component label of every point (0-based) among 26-connected occupied voxels."""
    if len(points_m) == 0:
        return np.zeros(0, dtype=np.intp)
    inverse, row, col, voxels = voxel_neighbours(points_m, voxel_m)
    graph = coo_matrix((np.ones(len(row)), (row, col)), shape=(voxels, voxels))
    _, component = connected_components(graph, directed=False)
    return component[inverse].astype(np.intp)  # type: ignore[no-any-return]


def drop_small(labels: NDArray[np.intp], min_points: int) -> NDArray[np.intp]:
    """Labels with clusters of fewer than ``min_points`` points set to :data:`NOISE`."""
    out = labels.copy()
    valid = labels >= 0
    counts = np.bincount(labels[valid]) if valid.any() else np.zeros(0, dtype=np.intp)
    small = valid & (counts[np.where(valid, labels, 0)] < min_points)
    out[small] = NOISE
    return out


def apply_grid_prior(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    grid: GridPrior,
    base_height_m: float,
) -> NDArray[np.intp]:
    """:func:`~fieldapp.recon.grid.apply_grid_prior_nodes` with the settings' grid."""
    return apply_grid_prior_nodes(points_m, labels, prior_nodes(grid), base_height_m, [])


def order_by_position(positions_m: NDArray[np.float64], row_gap_m: float) -> list[int]:
    """Indices of plants at ``positions_m`` (N, 2) in reading order: rows by y (a new row when
    the gap in y exceeds ``row_gap_m``), then x within a row. Ids numbered in this order stay
    the same when the plot is scanned again."""
    by_y = sorted(range(len(positions_m)), key=lambda i: float(positions_m[i, 1]))
    rows: list[list[int]] = []
    for index in by_y:
        if rows and positions_m[index, 1] - positions_m[rows[-1][-1], 1] <= row_gap_m:
            rows[-1].append(index)
        else:
            rows.append([index])
    return [i for row in rows for i in sorted(row, key=lambda i: float(positions_m[i, 0]))]


@dataclass(frozen=True)
class Plant:
    """One plant: its id (1-based, in reading order), its traits and its points; whether it
    was found from a stem (``False``: a density cluster where no stem was seen), the share of
    its points that another stem reaches almost as soon, and its (row, column) in the planting
    grid (1-based) when there is one."""

    id: int
    traits: PlantTraits
    cloud: Cloud
    from_stem: bool = True
    ambiguous_share: float = 0.0
    grid_cell: tuple[int, int] | None = None


@dataclass
class PlantSearch:
    """The plants and what the search had to decide on the way (for ``report.json``):

    - ``splits``: connected canopies (one density cluster) split between plants by their stems;
    - ``merges``: stem candidates merged into a stronger one nearby, and density clusters
      joined into one plant at one grid node;
    - ``missing_cells``: grid cells (row, column) where no plant was found though the captures
      saw the ground there;
    - ``unseen_cells``: grid cells outside what the captures saw (a mission that visited part
      of the plot): neither found nor missing;
    - ``extra_plants``: ids of plants standing at no grid cell;
    - ``meets``: plant id -> the plant its widest extent meets (:func:`widest_meets`): its width
      may go on into that plant, or end on a piece of it;
    - ``grid_fit``: how the planting grid was moved onto the stems, when it was."""

    plants: list[Plant]
    splits: list[list[int]] = field(default_factory=list)
    merges: list[str] = field(default_factory=list)
    missing_cells: list[tuple[int, int]] = field(default_factory=list)
    unseen_cells: list[tuple[int, int]] = field(default_factory=list)
    extra_plants: list[int] = field(default_factory=list)
    meets: dict[int, int] = field(default_factory=dict)
    grid_fit: GridFit | None = None
    cloud: Cloud | None = None
    """The cloud the plants were measured in: the one searched and the doubtful points that
    joined its plants (:func:`~fieldapp.recon.attach.attach_doubtful`)."""
    joined: int = 0
    """How many doubtful points joined a plant."""

    def warnings(self, flag_ambiguous_share: float) -> list[str]:
        """One line per plant that may hold another's points, per missing grid cell (as a
        list) and per plant off the grid."""
        lines = [
            f"plant {p.id}: {100 * p.ambiguous_share:.1f} % of its points could belong to a "
            "neighbour (canopies touch)"
            for p in self.plants
            if p.ambiguous_share > flag_ambiguous_share
        ]
        if self.meets:
            named = ", ".join(f"{p} (plant {o})" for p, o in sorted(self.meets.items()))
            lines.append(f"plants that {MEETS_WARNING}: {named}")
        fit = self.grid_fit
        if fit is not None and fit.applied:
            lines.append(
                f"planting grid fitted to {fit.stems} stems: it stood up to "
                f"{100 * fit.moved_m:.0f} cm ({fit.turned_deg:.1f} deg) off them where the map "
                "frame put it; the base's localisation, or the plan's grid, is off by that much "
                "(plants keep the map positions the base's reports give)"
            )
        if self.missing_cells:
            cells = ", ".join(f"row {r} column {c}" for r, c in self.missing_cells)
            lines.append(f"{len(self.missing_cells)} planting-grid cells without a plant: {cells}")
        if self.unseen_cells:
            lines.append(
                f"{len(self.unseen_cells)} planting-grid cells outside what the captures saw "
                "(not searched)"
            )
        if self.extra_plants:
            ids = ", ".join(str(i) for i in self.extra_plants)
            lines.append(f"{len(self.extra_plants)} plants off the planting grid: {ids}")
        return lines


def find_plants(
    cloud: Cloud,
    soil_m: NDArray[np.float64],
    settings: PlantSettings,
    ground_radius_m: float,
    grid: GridNodes | None = None,
) -> list[Plant]:
    """Split the plot's plant cloud (field frame) into plants and measure each one."""
    return search_plants(cloud, soil_m, settings, ground_radius_m, grid).plants


def search_plants(
    cloud: Cloud,
    soil_m: NDArray[np.float64],
    settings: PlantSettings,
    ground_radius_m: float,
    grid: GridNodes | None = None,
    doubtful: Cloud | None = None,
) -> PlantSearch:
    """Plants from their stems (density clusters where no stem is seen), measured, in reading
    order, with the planting grid ``grid`` (field frame) as a prior when given; the
    ``doubtful`` points (:func:`~fieldapp.recon.filters.split_outliers`) take no part in the
    search, and join the plants they touch before these are measured."""
    if grid is None and settings.grid is not None:
        grid = prior_nodes(settings.grid)
    merges: list[str] = []
    stems: list[Stem] = []
    # the plan-view tree over the soil, built once (0.04 s for a 3 x 3 plot): the stems' local
    # ground, the plants' soil and the grid's seen nodes all ask it
    soil_tree = cKDTree(soil_m[:, :2]) if len(soil_m) else None
    grid_fit: GridFit | None = None
    claims: NodeClaims | None = None
    if settings.stems.enabled and len(cloud):
        stems, merged = find_stems(cloud.points, soil_m, settings.stems, soil_tree)
        if merged:
            merges.append(f"{merged} stem candidates merged into a stronger stem nearby")
        if grid is not None:
            grid, grid_fit = fitted_to_stems(grid, np.array([stem.xy_m for stem in stems]))
            stems = stems + stems_at_empty_nodes(
                cloud.points, soil_m, stems, grid, settings.stems, soil_tree
            )
            claims = node_claims(grid, np.array([stem.xy_m for stem in stems]).reshape(-1, 2))
    coloured = _coloured(cloud)
    labels, ambiguous = _labels(
        cloud.points, stems, settings, merges, claims, cloud.colors if coloured else None
    )
    if not stems and grid is not None:
        labels = apply_grid_prior_nodes(
            cloud.points, labels, grid, 2 * settings.base_slice_m, merges
        )
    feet = np.array([stem.xy_m for stem in stems]).reshape(-1, 2)
    _parts_seen_apart(
        cloud,
        labels,
        ambiguous,
        feet,
        soil_m,
        soil_tree,
        coloured,
        settings,
        merges,
    )
    cloud, labels, ambiguous, joined = _with_loose(
        cloud, labels, ambiguous, doubtful, soil_m, soil_tree, coloured, merges
    )

    def measured(notes: list[str] | None = None) -> tuple[list[Plant], dict[int, int]]:
        return _measured(
            cloud,
            soil_m,
            soil_tree,
            labels,
            ambiguous,
            len(stems),
            settings,
            ground_radius_m,
            coloured,
            notes,
        )

    plants, plant_labels = measured(merges)
    if _merge_shared_bases(labels, plants, plant_labels, settings.stems.min_separation_m, merges):
        plants, plant_labels = measured()  # the labels merged in place
    search = PlantSearch(plants, merges=merges, grid_fit=grid_fit, cloud=cloud, joined=joined)
    if grid is not None:
        _place_on_grid(search, grid, soil_m, soil_tree)
    search.splits = _splits(cloud.points, labels, plant_labels, settings.cluster_voxel_m)
    search.meets = widest_meets(search.plants, search.splits, settings.cluster_voxel_m)
    return search


def _with_loose(
    cloud: Cloud,
    labels: NDArray[np.intp],
    ambiguous: NDArray[np.bool_],
    doubtful: Cloud | None,
    soil_m: NDArray[np.float64],
    soil_tree: cKDTree | None,
    coloured: bool,
    merges: list[str],
) -> tuple[Cloud, NDArray[np.intp], NDArray[np.bool_], int]:
    """The loose points joined to the plants they reach
    (:func:`~fieldapp.recon.attach.attach_doubtful`), never ambiguous: the ``doubtful`` points
    (:func:`~fieldapp.recon.filters.split_outliers`), appended to ``cloud`` with their plant,
    and the cloud's own :data:`FRAGMENT` points, labelled in place (:data:`NOISE` where they
    reach none). The two are searched together, so a leaf's tip the outlier filters left in
    pieces (a few points kept, a few doubtful) is followed through both. Returns the cloud, its
    labels and doubts, and how many doubtful points joined. A group joins across
    :data:`~fieldapp.recon.attach.ATTACH_GAP_M` where every point of it floats: more than
    :data:`ON_THE_SOIL_M` above the local ground (``soil_m``) and green by its own colour
    (:func:`~fieldapp.recon.filters.not_green`, the pass-through's rule), on a plot with
    colour (``coloured``). Else it may be a clod (clods cut from the soil float
    too, their lower part kept as soil) or, a piece of the cloud on the soil, a weed: a
    doubtful group then joins within
    :data:`~fieldapp.recon.attach.ATTACH_GROUND_GAP_M`, a group with a piece in it only point
    by point.

    Why the fragments: a drooping tip seen by few views, at the plant's widest extent, came
    through as groups of 40-100 points 1-6 cm from the rest of its leaf, which density
    clustering drops as too small to be a plant; on an independent renderer's touching plots
    that took 4-5.5 cm off the widths of the plants they ended."""
    fragments = np.flatnonzero(labels == FRAGMENT)
    labels[fragments] = NOISE
    doubtful = doubtful if doubtful is not None else Cloud.empty()
    loose = Cloud.concatenate([cloud.select(fragments), doubtful])
    if len(loose) == 0:
        return cloud, labels, ambiguous, 0
    floating = np.zeros(len(loose), dtype=bool)
    if coloured:
        ground = local_ground_z_m(soil_m, loose.points[:, :2], 0.0, soil_tree)
        clear = loose.points[:, 2] - ground > ON_THE_SOIL_M
        floating = clear & ~not_green(loose.colors)
    # a piece on the soil may be a weed, a doubtful group there a clod (ATTACH_GROUND_GAP_M)
    pieces = np.arange(len(loose)) < len(fragments)
    on_soil_gap_m = np.where(pieces, 0.0, ATTACH_GROUND_GAP_M)
    gaps_m = np.where(floating, ATTACH_GAP_M, on_soil_gap_m)
    found = attach_doubtful(cloud.points, labels, loose.points, gaps_m=gaps_m)
    own, theirs = found[: len(fragments)], found[len(fragments) :]
    labels[fragments] = own
    if (own >= 0).any():
        merges.append(
            f"{int((own >= 0).sum())} points of fragments too small to be plants joined to the "
            "plant they reach"
        )
    joins = theirs >= 0
    if not joins.any():
        return cloud, labels, ambiguous, 0
    joined = doubtful.select(joins)
    return (
        Cloud.concatenate([cloud, joined]),
        np.concatenate([labels, theirs[joins]]),
        np.concatenate([ambiguous, np.zeros(len(joined), dtype=bool)]),
        len(joined),
    )


PART_SHARE = 0.1
"""A group no stem reaches that holds fewer points than this share of the median plant found
from a stem is a part of a plant, not a plant (:func:`_parts_seen_apart`): plants no stem was
seen for (a plot's edge, the foot hidden under the neighbours) held 0.15-1.0 of it on an
independent renderer's touching plots, leaves seen apart from their plants 0.01-0.04."""
MIN_STEMS_FOR_PARTS = 3
"""Plants found from stems needed before a group is judged small against them."""
ON_THE_SOIL_M = 0.03
"""A small group whose lowest point is within this of its ground may stand on the soil (a late
seedling whose stem was not found, a leaf's tip resting there): it is left to the other rules."""
PART_REACH_M = 0.25
"""A leaf part seen apart joins the plant with a point within this of it (a leaf's unseen
stretch between them); farther from every plant it is not counted."""


def _parts_seen_apart(
    cloud: Cloud,
    labels: NDArray[np.intp],
    ambiguous: NDArray[np.bool_],
    feet_m: NDArray[np.float64],
    soil_m: NDArray[np.float64],
    soil_tree: cKDTree | None,
    coloured: bool,
    settings: PlantSettings,
    merges: list[str],
) -> None:
    """Small groups no stem reaches (under :data:`PART_SHARE` of the median plant found from a
    stem, ``feet_m`` (S, 2) the stems' feet) are parts of plants, not plants (``labels`` and
    ``ambiguous`` changed in place):

    - not green (``coloured`` points, :func:`~fieldapp.recon.exg.not_green_group`) and
      near the soil (lowest point within :data:`FLOATING_M`; higher up it is an object among
      the plants, :func:`_foreign`): soil or residue lifted into the plants beside a leaf or a
      straw (an independent renderer's pale straw is weakly green, and the leaves' rim rules
      grow from it over the soil around), not counted;
    - green and floating (lowest point more than :data:`ON_THE_SOIL_M` above its ground): a
      leaf whose middle no camera saw, its outer part cut off by the gap. It joins the plant
      whose foot its base (:func:`~fieldapp.recon.traits.base_xy_m`) stands within
      ``stems.min_separation_m`` of (the rule two plants' bases are merged by,
      :func:`_merge_shared_bases`); else the plant with the point nearest it (within
      :data:`PART_REACH_M`), unless another plant's foot is nearer it (plan view) by more
      than ``stems.ambiguity_margin_m``; then, or with no plant within reach, it is not
      counted. A plant no stem was seen for stands at its base. A joined part is a guess,
      counted as ambiguous in the report. On an independent renderer's plots these parts
      were 207-1 873 points, 12-40 cm "plants" off the planting grid, on five of eight
      touching plots.

    A small green group on the soil is left alone: a late seedling whose stem was not found
    looks the same."""
    stem_count, margin_m = len(feet_m), settings.stems.ambiguity_margin_m
    if stem_count < MIN_STEMS_FOR_PARTS or labels.max(initial=-1) < stem_count:
        return
    by_label = _members_by_label(labels, int(labels.max()) + 1)
    counts = np.array([len(members) for members in by_label])
    small = PART_SHARE * float(np.median(counts[:stem_count]))
    parts = [lab for lab in range(stem_count, len(counts)) if 0 < counts[lab] < small]
    if not parts:
        return
    # the plants a part may belong to: the stems that kept their points (a leaf's end merged
    # into its plant has none) and the groups too large to be parts, each at its foot
    feet = np.full((len(counts), 2), np.inf)
    feet[:stem_count] = feet_m
    for label in range(stem_count, len(counts)):
        if counts[label] >= small:
            feet[label] = base_xy_m(cloud.points[by_label[label]], settings.base_slice_m)
    is_plant = (counts >= small) | ((np.arange(len(counts)) < stem_count) & (counts > 0))
    joined, dropped, not_green = 0, 0, 0
    for label in parts:
        members = by_label[label]
        part = cloud.points[members]
        ground = local_ground_z_m(soil_m, part[:, :2], float(part[:, 2].min()), soil_tree)
        low = float(part[:, 2].min() - np.median(ground))
        if coloured and not_green_group(cloud.colors[members]):
            if low <= FLOATING_M:  # higher up: an object among the plants (_foreign)
                labels[members] = NOISE
                not_green += len(members)
            continue
        if low <= ON_THE_SOIL_M:
            continue
        base = base_xy_m(part, settings.base_slice_m)
        on_base = np.where(is_plant, np.linalg.norm(feet - base, axis=1), np.inf)
        if on_base.min() <= settings.stems.min_separation_m:
            owner: int | None = int(np.argmin(on_base))
        else:
            owner = _nearest_plant_point(cloud.points, labels, is_plant, part, PART_REACH_M)
            centre = part[:, :2].mean(axis=0)
            to_foot = np.where(is_plant, np.linalg.norm(feet - centre, axis=1), np.inf)
            if owner is not None and to_foot[owner] > to_foot.min() + margin_m:
                owner = None
        if owner is None:
            labels[members] = NOISE
            dropped += len(members)
        else:
            labels[members] = owner
            ambiguous[members] = True
            joined += len(members)
    if joined:
        merges.append(
            f"{joined} points of leaves seen apart from their plants (small groups no stem "
            "reaches, above the soil) joined to the plant nearest them"
        )
    if dropped:
        merges.append(
            f"{dropped} points of leaves seen apart from their plants (small groups no stem "
            "reaches, above the soil) whose plant is not clear, not counted"
        )
    if not_green:
        merges.append(
            f"{not_green} points in small groups no stem reaches, near the soil and not green "
            "(soil or residue beside a leaf), not counted as plants"
        )


def _members_by_label(labels: NDArray[np.intp], count: int) -> list[NDArray[np.intp]]:
    """The indices of the points of each label 0..``count`` - 1 (``labels`` (N,); NOISE and
    unreached points left out), from one stable sort: in the order the points are."""
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(count + 1))
    return [order[bounds[label] : bounds[label + 1]] for label in range(count)]


def _nearest_plant_point(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    is_plant: NDArray[np.bool_],
    part_m: NDArray[np.float64],
    reach_m: float,
) -> int | None:
    """The label (one of ``is_plant`` (L,)) of the point nearest ``part_m`` (K, 3) within
    ``reach_m``, if any (only the points in the part's box grown by ``reach_m`` are searched)."""
    low, high = part_m.min(axis=0) - reach_m, part_m.max(axis=0) + reach_m
    inside = np.flatnonzero(np.all((points_m >= low) & (points_m <= high), axis=1))
    near = inside[labels[inside] >= 0]
    near = near[is_plant[labels[near]]]
    if len(near) == 0:
        return None
    distance, index = cKDTree(points_m[near]).query(part_m, distance_upper_bound=reach_m)
    closest = int(np.argmin(distance))
    if not np.isfinite(distance[closest]):
        return None
    return int(labels[near[index[closest]]])


def _merge_shared_bases(
    labels: NDArray[np.intp],
    plants: list[Plant],
    plant_labels: dict[int, int],
    min_separation_m: float,
    merges: list[str],
) -> bool:
    """Plants whose measured bases stand within ``min_separation_m`` of a taller one's are
    parts of it: their labels become its label (in place), by the rule stems are kept by
    (:func:`stems.merged_into`). Two stems are never kept that close, but a stem found farther
    off (a drooping leaf's tip in very noisy depth, its veil of mixed pixels read as a column)
    can take a plant's lower part along the plant, and both then stand on the one base.
    Returns whether any plant was merged."""
    xy = np.array([[p.traits.x_m, p.traits.y_m] for p in plants]).reshape(-1, 2)
    into = merged_into(xy, np.array([p.traits.height_m for p in plants]), min_separation_m)
    for plant, host in zip(plants, into, strict=True):
        if plants[host] is not plant:
            labels[labels == plant_labels[plant.id]] = plant_labels[plants[host].id]
    merged = int(np.count_nonzero(into != np.arange(len(plants))))
    if merged:
        merges.append(f"{merged} plants standing on another plant's base merged into it")
    return merged > 0


def _labels(
    points_m: NDArray[np.float64],
    stems: list[Stem],
    settings: PlantSettings,
    merges: list[str],
    claims: NodeClaims | None = None,
    colors: NDArray[np.uint8] | None = None,
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Per point: its stem (0..S-1), a density cluster (S..) where no stem reaches, a
    :data:`FRAGMENT` too small to be one, or :data:`NOISE`; and whether it is ambiguous
    between two stems. ``claims``: where a planting grid places the stems
    (:func:`fieldapp.recon.grid.node_claims`); ``colors``: the points' colours where they
    tell plant from not (:func:`_join_fragments`)."""
    labels = np.full(len(points_m), NOISE, dtype=np.intp)
    ambiguous = np.zeros(len(points_m), dtype=bool)
    refused = np.zeros(len(points_m), dtype=bool)
    if stems:
        s = settings.stems
        xy = np.array([stem.xy_m for stem in stems])
        graph = voxel_graph(points_m, s.graph_voxel_m)
        states = stem_states(graph, xy, s)
        junctions = s.junction_radius_m > 0.0
        # the leaves' ends are judged on the assignment without the steps across gaps: with
        # them an end standing under its neighbours' leaves steps onto them and is no end
        assignment = assign_by_settings(points_m, xy, s, graph, states, junctions=False)
        labels[:] = assignment.stem
        ambiguous = assignment.ambiguous
        kept = np.arange(len(stems))
        if s.leaf_ends:
            ambiguous, kept = _merge_leaf_ends(
                graph, stems, assignment, labels, ambiguous, s, merges, claims
            )
        if junctions:
            again = assign_by_settings(points_m, xy[kept], s, graph, states)
            labels[:] = np.where(again.stem >= 0, kept[np.maximum(again.stem, 0)], UNREACHED)
            ambiguous = again.ambiguous
        guessed, refused = _join_fragments(
            points_m, labels, settings.cluster_voxel_m, s.ambiguity_margin_m, merges, colors
        )
        if s.follow_leaves:
            feet = np.array([[*stem.xy_m, stem.ground_z_m] for stem in stems])
            moved = follow_leaves(points_m, labels, ambiguous, feet)
            if len(moved):
                merges.append(f"{len(moved)} points given to the leaf that runs on through them")
            # a ribbon's claim is a guess too: a ribbon that ran off its leaf's tip onto a
            # neighbour's leaf made a 5 x 5 touching plot's p55 18 cm too wide, unflagged
            guessed[moved] = True
        ambiguous |= guessed  # for the report only: the ribbons follow the assignment's doubts
    rest = np.flatnonzero((labels == UNREACHED) & ~refused)
    if len(rest):
        clusters = drop_small(
            voxel_components(points_m[rest], settings.cluster_voxel_m), settings.min_points
        )
        labels[rest] = np.where(clusters >= 0, clusters + len(stems), FRAGMENT)
    return labels, ambiguous


def _merge_leaf_ends(
    graph: VoxelGraph,
    stems: list[Stem],
    assignment: Assignment,
    labels: NDArray[np.intp],
    ambiguous: NDArray[np.bool_],
    s: StemSettings,
    merges: list[str],
    claims: NodeClaims | None = None,
) -> tuple[NDArray[np.bool_], NDArray[np.intp]]:
    """Stems that are the end of another plant's leaf come down to the soil
    (:func:`fieldapp.recon.geodesic.leaf_ends`; those the grid's ``claims`` put off it, or at
    the node of the stem they would join, by the lower share)
    relabelled as that plant in ``labels`` (in place, stem labels only); returns
    ``ambiguous`` without the doubts they settle, and the stems kept (indices, ascending)."""
    into = leaf_ends(
        graph,
        np.array([[*stem.xy_m, stem.ground_z_m] for stem in stems]),
        assignment,
        s.seed_radius_m,
        s.seed_height_m,
        s.reach_m,
        s.leaf_end_share,
        s.leaf_end_slack_m,
        claims,
        s.leaf_end_share_off_grid,
    )
    ended = into != np.arange(len(stems))
    kept = np.flatnonzero(~ended)
    if not ended.any():
        return ambiguous, kept
    reached = labels >= 0
    labels[reached] = into[labels[reached]]
    # a doubt between a leaf's end and the plant it grows from is none once they are one
    runner = assignment.runner_up
    settled = reached & (runner >= 0)
    settled[settled] = labels[settled] == into[runner[settled]]
    merges.append(
        f"{int(ended.sum())} stems found where a leaf comes down to the soil merged into the "
        "plant the leaf grows from"
    )
    return ambiguous & ~settled, kept


def _join_fragments(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    voxel_m: float,
    margin_m: float,
    merges: list[str],
    colors: NDArray[np.uint8] | None = None,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Points no stem reaches along the plant (the graph joins only voxels 1.5 cm apart) but
    that density clustering puts with reached points go to the stem of the nearest reached
    point of their cluster: a leaf seen with a gap at its base stays with its plant. Returns
    (N,) the joined points that are a guess: where the cluster holds two stems' points
    (canopies touch), those whose nearest point of another stem there is less than
    ``margin_m`` farther than the one they went to (a gap-cut leaf between two plants went to
    the nearer: touching depth-only irregular seed 87, 2 340 points of a leaf 13 cm too narrow
    joined to the neighbour, 12 cm too wide, neither flagged).

    With ``colors`` (N, 3), a fragment (the points to join that touch one another) whose
    colour is neither green nor of any hue (:func:`~fieldapp.recon.exg.not_green_group`,
    :func:`~fieldapp.recon.exg.grey_group`: grey, white, near black) is an object a plant's
    leaves touch, not a leaf: it is refused, left out of every plant, and the (N,) refused
    points are returned too. On an independent renderer's plots: reference spheres and their
    stands, 103-1 318 points 11-97 cm up, that raised the heights of the plants they joined by
    up to 24 cm. A brown or yellow fragment is joined: a leaf's tip seen with the colour of the
    soil beside it looks so (15-28 points at the top of seedlings and tall plants alike)."""
    guessed = np.zeros(len(points_m), dtype=bool)
    refused = np.zeros(len(points_m), dtype=bool)
    unreached = labels == UNREACHED
    if not unreached.any() or unreached.all():
        return guessed, refused
    clusters = voxel_components(points_m, voxel_m)
    has_stem = np.zeros(int(clusters.max()) + 1, dtype=bool)
    has_stem[clusters[~unreached]] = True
    joined = np.flatnonzero(unreached & has_stem[clusters])
    if colors is not None and len(joined):
        fragments = voxel_components(points_m[joined], voxel_m)
        for fragment in _by_cluster(fragments, np.arange(len(joined))):
            seen = colors[joined[fragment]]
            if not_green_group(seen) and grey_group(seen):
                refused[joined[fragment]] = True
        if refused.any():
            merges.append(
                f"{int(refused.sum())} points neither green nor of any hue touching plants but "
                "not reached along them (an object among the plants: a reference sphere, a "
                "stand, a label) not joined"
            )
            joined = joined[~refused[joined]]
    if len(joined) == 0:
        return guessed, refused
    reached = np.flatnonzero(~unreached & np.isin(clusters, clusters[joined]))
    shared = []  # joined in a cluster of two plants or more: there they may be the other's
    for r, j in zip(*(_by_cluster(clusters, part) for part in (reached, joined)), strict=True):
        distance, nearest = cKDTree(points_m[r]).query(points_m[j])
        labels[j] = labels[r[nearest]]
        guessed[j] = _second_stem_near(points_m, labels, r, j, distance, margin_m)
        if len(np.unique(labels[r])) > 1:
            shared.append(j)
    merges.append(f"{len(joined)} points not reached along a plant joined to the nearest plant")
    among = np.concatenate(shared) if shared else np.zeros(0, dtype=np.intp)
    stems = np.flatnonzero(_joined_shares(labels, among) > JOINED_SHARE)
    if len(stems):
        guessed[among[np.isin(labels[among], stems)]] = True
        merges.append(
            f"{len(stems)} plants with more than {100 * JOINED_SHARE:.0f} % of their points "
            "joined so (cut from their stems: a neighbour's leaves or body, perhaps) flagged"
        )
    return guessed, refused


def _joined_shares(labels: NDArray[np.intp], joined: NDArray[np.intp]) -> NDArray[np.float64]:
    """Per stem label (0..max), the share of its points (``labels`` >= 0) that are among
    ``joined`` (indices)."""
    size = int(labels.max(initial=-1)) + 1
    total = np.bincount(labels[labels >= 0], minlength=size)
    part = np.bincount(labels[joined], minlength=size)
    shares: NDArray[np.float64] = part / np.maximum(total, 1)
    return shares


def _by_cluster(clusters: NDArray[np.intp], members: NDArray[np.intp]) -> list[NDArray[np.intp]]:
    """``members`` (indices) grouped by their cluster, in cluster order."""
    order = np.argsort(clusters[members], kind="stable")
    _, starts = np.unique(clusters[members][order], return_index=True)
    return np.split(members[order], starts[1:])


def _second_stem_near(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    reached: NDArray[np.intp],
    joined: NDArray[np.intp],
    distance_m: NDArray[np.float64],
    margin_m: float,
) -> NDArray[np.bool_]:
    """(len(joined),) for the points of one cluster: whether a ``reached`` point of another
    stem than the one each ``joined`` point went to (its nearest reached point, ``distance_m``
    away) lies within ``margin_m`` more (one k-d tree per stem over its points there)."""
    other = np.full(len(joined), np.inf)
    went_to, reach = labels[joined], distance_m + margin_m
    stems = np.unique(labels[reached])
    for stem in stems if len(stems) > 1 else ():
        asked = np.flatnonzero(went_to != stem)
        if len(asked) == 0:
            continue
        members = reached[labels[reached] == stem]
        found, _ = cKDTree(points_m[members]).query(
            points_m[joined[asked]], distance_upper_bound=float(reach[asked].max())
        )
        other[asked] = np.minimum(other[asked], found)
    return other < reach


def _measured(
    cloud: Cloud,
    soil_m: NDArray[np.float64],
    soil_tree: cKDTree | None,
    labels: NDArray[np.intp],
    ambiguous: NDArray[np.bool_],
    stem_count: int,
    settings: PlantSettings,
    ground_radius_m: float,
    coloured: bool = False,
    notes: list[str] | None = None,
) -> tuple[list[Plant], dict[int, int]]:
    """The labelled groups large and tall enough to be plants, measured, ids in reading order;
    and the label each plant id came from. Where the points are ``coloured``
    (:func:`_coloured`), a group no stem reaches that floats above the soil and is not green
    (:func:`_foreign`) is not a plant; ``notes`` is told of each."""
    measured: list[tuple[PlantTraits, Cloud, bool, float]] = []
    measured_labels: list[int] = []
    for label, members in enumerate(_members_by_label(labels, int(labels.max(initial=-1)) + 1)):
        if len(members) < settings.min_points:
            continue
        plant = cloud.select(members)
        traits = measure_plant(
            plant.points,
            _soil_near(soil_m, soil_tree, plant.points, ground_radius_m),
            settings.base_slice_m,
            ground_radius_m,
            settings.top_support_points,
            settings.top_support_radius_m,
            width_points(plant),
        )
        low = _foreign(plant, traits) if label >= stem_count and coloured else None
        if low is not None:
            if notes is not None:
                x, y = plant.points[:, :2].mean(axis=0)
                notes.append(
                    f"{len(members)} points no stem reaches, {100 * low:.0f} cm above the soil "
                    f"around ({x:.2f}, {y:.2f}) m and not green, not counted as a plant (a "
                    "reference sphere or its stand, an object among the plants)"
                )
            continue
        if traits.height_m >= settings.min_height_m:
            share = float(np.mean(ambiguous[members]))
            measured.append((traits, plant, label < stem_count, share))
            measured_labels.append(label)
    positions = np.array([[m[0].x_m, m[0].y_m] for m in measured]).reshape(-1, 2)
    reading = order_by_position(positions, settings.row_gap_m)
    plants = [Plant(i + 1, *measured[index]) for i, index in enumerate(reading)]
    return plants, {i + 1: measured_labels[index] for i, index in enumerate(reading)}


FLOATING_M = 0.15
"""A group of points no stem reaches whose lowest point stands this far above its ground does
not grow from the soil where it is seen (:func:`_foreign`)."""


def _coloured(cloud: Cloud) -> bool:
    """Whether the plot's points carry colour that tells plant from not (some clearly green):
    not so for depth-only captures, separated by geometry."""
    sample = cloud.colors[:: max(1, len(cloud) // 20000)]
    return bool(len(sample)) and float(np.quantile(excess_green(sample), 0.9)) > 2 * NOT_GREEN_EXG


def _foreign(plant: Cloud, traits: PlantTraits) -> float | None:
    """How high a group of points no stem reaches floats above its ground when it is not a
    plant (else ``None``): its lowest point more than :data:`FLOATING_M` up *and* its median
    colour not green: the cap of a reference sphere on its stand among tall plants (an
    independent renderer's: 399 points 67-77 cm up, a 77 cm "plant" off the grid), a label, a
    hand. A green group up there is a plant's top whose lower part was not seen, and stays
    one."""
    low = float(plant.points[:, 2].min()) - traits.ground_z_m
    if low <= FLOATING_M or not not_green_group(plant.colors):
        return None
    return low


def _soil_near(
    soil_m: NDArray[np.float64],
    tree: cKDTree | None,
    points_m: NDArray[np.float64],
    margin_m: float,
) -> NDArray[np.float64]:
    """The soil points within ``margin_m`` (plan view) of the box around ``points_m``: all a
    plant's traits look at, found without scanning the plot's soil once per plant."""
    if tree is None:
        return soil_m
    low, high = points_m[:, :2].min(axis=0), points_m[:, :2].max(axis=0)
    radius = float(np.linalg.norm(high - low)) / 2.0 + margin_m
    near = np.asarray(tree.query_ball_point((low + high) / 2.0, radius), dtype=np.intp)
    return soil_m[near]


def _place_on_grid(
    search: PlantSearch, grid: GridNodes, soil_m: NDArray[np.float64], soil_tree: cKDTree | None
) -> None:
    """Each plant to the grid node its base stands at (within the snap radius), one plant per
    node (the nearest); the others are extra; the nodes left are missing where the soil sample
    (M, 3) has ground within the snap radius, unseen elsewhere (every node counts as seen
    without a soil sample)."""
    bases = np.array([[p.traits.x_m, p.traits.y_m] for p in search.plants]).reshape(-1, 2)
    nodes, placed = at_nodes(grid, bases)
    owner = {int(index): int(node) for node, index in zip(nodes, placed, strict=True)}
    for index, plant in enumerate(search.plants):
        if index not in owner:
            search.extra_plants.append(plant.id)
            continue
        at = owner[index]
        search.plants[index] = replace(plant, grid_cell=(int(grid.row[at]), int(grid.column[at])))
    seen = np.ones(len(grid.xy_m), dtype=bool)
    if soil_tree is not None:
        distance, _ = soil_tree.query(grid.xy_m)
        seen = distance <= grid.snap_radius_m
    taken = set(owner.values())
    for node in range(len(grid.xy_m)):
        if node not in taken:
            cells = search.missing_cells if seen[node] else search.unseen_cells
            cells.append((int(grid.row[node]), int(grid.column[node])))


def widest_meets(plants: list[Plant], splits: list[list[int]], reach_m: float) -> dict[int, int]:
    """Plant id -> the plant (of its ``splits`` group: one density cluster) that its widest
    extent, its points within :data:`WIDEST_M` of the circle enclosing it (plan view), comes
    within ``reach_m`` of (the one most of those points are near). Such a plant's width is where
    it was cut from its neighbour, not where a leaf was seen to end: an unflagged plant 11 cm
    too narrow, whose leaf tip past a 4 cm gap went to the stem it touched, ended 2 cm from
    that plant (an unseen touching plot; over the touching bench, 9 of the 23 plants more than
    3 cm too narrow, and 30 of the 429 within 2 cm, RECONSTRUCTION.md). The points a width
    is measured on, on both sides: a mixed pixel (:attr:`Cloud.mixed`) is in the air past a
    leaf's edge, neither where it ends nor a neighbour's leaf."""
    by_id = {plant.id: plant for plant in plants}
    meets: dict[int, int] = {}
    for group in splits:
        clouds = [width_points(by_id[plant_id].cloud) for plant_id in group]
        owner = np.repeat(np.array(group), [len(cloud) for cloud in clouds])
        tree = cKDTree(np.concatenate(clouds))
        for plant_id, points in zip(group, clouds, strict=True):
            circle = by_id[plant_id].traits.circle  # measured on these points
            off = np.hypot(points[:, 0] - circle.centre_x_m, points[:, 1] - circle.centre_y_m)
            widest = points[off >= circle.radius_m - WIDEST_M]
            near = owner[list(itertools.chain(*tree.query_ball_point(widest, reach_m)))]
            near = near[near != plant_id]
            if len(near):
                others, counts = np.unique(near, return_counts=True)
                meets[plant_id] = int(others[np.argmax(counts)])
    return meets


def _splits(
    points_m: NDArray[np.float64],
    labels: NDArray[np.intp],
    plant_labels: dict[int, int],
    voxel_m: float,
) -> list[list[int]]:
    """Groups of plant ids that density clustering would have taken for one plant."""
    if not plant_labels:
        return []
    plant_of_label = np.full(int(labels.max(initial=0)) + 2, 0, dtype=np.intp)
    for plant_id, label in plant_labels.items():
        plant_of_label[label] = plant_id
    ids = np.where(labels >= 0, plant_of_label[np.maximum(labels, 0)], 0)
    kept = ids > 0
    clusters = voxel_components(points_m[kept], voxel_m)
    pairs = np.unique(clusters.astype(np.int64) << 32 | ids[kept].astype(np.int64))
    groups: dict[int, list[int]] = {}
    for cluster, plant_id in zip(pairs >> 32, pairs & 0xFFFFFFFF, strict=True):
        groups.setdefault(int(cluster), []).append(int(plant_id))
    return sorted(sorted(g) for g in groups.values() if len(g) > 1)
