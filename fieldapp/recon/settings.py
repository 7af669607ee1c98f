"""Parameters of the reconstruction, with the paper's values as defaults.

Every length carries its unit. The model lives here and is mounted in
:class:`fieldapp.settings.Settings` as ``reconstruction``.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class CropSettings(_Section):
    """Back-projection: keep what lies within ``radius_m`` of the camera (paper: 2.25 m)."""

    radius_m: float = Field(default=2.25, gt=0.0)
    min_depth_m: float = Field(default=0.5, ge=0.0)
    scale_to_rig: bool = True
    """``radius_m`` is the paper's, for its rig (cameras 1.3 m above the ground, stations
    1.6 m apart): on the ground it keeps 1.84 m around each camera, 1.15 station spacings, so
    that neighbouring stations overlap. On another rig (the calibration's ground and stations
    tell the cameras' height and spacing) the radius keeping the same reach in spacings is used
    (``backproject.rig_crop``): cameras 1.6 m high keep 2.44 m. Off: ``radius_m`` as it is."""


class GroundSettings(_Section):
    """Levelling: a RANSAC plane near the expected ground, refined per station."""

    ransac_distance_m: float = Field(default=0.01, gt=0.0)
    ransac_iterations: int = Field(default=300, ge=10)
    sample_points: int = Field(default=40_000, ge=500)
    search_band_m: float = Field(default=0.15, gt=0.0)
    max_tilt_deg: float = Field(default=15.0, gt=0.0, le=60.0)
    min_inlier_fraction: float = Field(default=0.3, gt=0.0, le=1.0)
    soil_band_m: float = Field(default=0.15, gt=0.0)
    soil_pixel_stride: int = Field(default=4, ge=1)
    soil_voxel_m: float = Field(default=0.02, gt=0.0)
    local_ground_radius_m: float = Field(default=0.15, gt=0.0)


class FilterSettings(_Section):
    """Plant filtering (paper: pass-through, ExG with Otsu, SOR k=35 1.5 sigma, ROR 8 mm / 5)."""

    pass_through_min_m: float = Field(default=0.01, ge=0.0)
    pass_through_max_m: float = Field(default=1.5, gt=0.0)
    pass_through_dull_min_m: float = Field(default=0.025, ge=0.0)
    """How far a point whose own colour is not green (``filters.not_green``: a leaf's rim grown
    back by the colour step's rim rules, or the soil they grew into; or a pixel without colour)
    must stand clear of the
    local ground: on an independent renderer's plots the rim rules grew 251 000 soil pixels
    against 3 200 of leaf, and the soil on clods and ridges 1-5 cm up joined the plants (a
    seedling 32 % soil and straw, 19 cm too wide)."""
    pass_through_continued_min_m: float = Field(default=0.05, ge=0.0)
    """How far a point of a leaf's surface followed past its green (``scans.continued_surfaces``:
    a tip whose colour mixes with the soil's, or yellows) must stand clear of the local ground:
    a leaf lying on the soil continues into it without a depth edge, and the soil's clods and
    ridges stand 1-5 cm up (the dull points' 2.5 cm let 300-600 soil points through on a
    seedling plot)."""
    exg_threshold: float | Literal["otsu"] = "otsu"
    sor_neighbors: int = Field(default=35, ge=2)
    sor_std_ratio: float = Field(default=1.5, gt=0.0)
    geometry_plant_min_m: float = Field(default=0.08, ge=0.0)
    """Without colour (plants told by geometry), how far above the local ground a connected
    group must reach to be a plant: clods and stones of a tilled seedbed reach 5-6 cm
    (``geometry_split.PLANT_MIN_M``); lower it for seedlings shorter than this."""
    sor_min_distance_m: float = Field(default=0.02, ge=0.0)
    """The statistical filter never removes a point whose mean distance to its neighbours is
    within this (``filters.sor_limit``): about 3 times the pixel footprint at the crop's 2.25
    m, where a surface seen once has its 35 nearest 2.2 footprints away on average. 0: the
    paper's limit alone."""
    sor_doubtful_distance_m: float = Field(default=0.04, ge=0.0)
    """A point the statistical filter removes whose mean distance to its neighbours is within
    this (and that passes the radius filter among such points) is *doubtful*: not used to
    find the plants, it then joins the plant it touches (``attach.attach_doubtful``), and is
    dropped where it touches none. A leaf's thin tip is sparse, seen by one station, and
    failed the floor above; kept outright, the same points bridged touching plants and moved
    whole leaves between them (RECONSTRUCTION.md, "Doubtful points"). At or under
    ``sor_min_distance_m``: none is doubtful (the paper's filter alone)."""
    ror_radius_m: float = Field(default=0.008, gt=0.0)
    ror_min_points: int = Field(default=1, ge=1)
    voxel_size_m: float = Field(default=0.002, gt=0.0)


class RegistrationSettings(_Section):
    """Global registration: a pose graph of every overlapping pair of stations.

    ``arrival_sigma_m``/``_deg``: the base's arrival uncertainty (one standard deviation per
    horizontal axis, and in yaw); ``level_sigma_*``: what levelling leaves of tilt and height.
    A correction beyond ``guard_sigmas`` of this expected error is rejected. Pairs sharing
    ``min_overlap_m2`` of ground (cells of ``overlap_cell_m``; or ``min_overlap_share`` of the
    stations' largest overlaps) are registered (GICP, coarse to
    fine over ``voxel_sizes_m``, the sizes at or below ``shared_cloud_m`` on the finest
    size's points, each with its own reach); an edge disagreeing with the solution by more than
    ``edge_tolerance_m``/``_deg`` is dropped. A station whose estimated uncertainty exceeds
    ``max_uncertainty_m``/``_deg`` is reported unreliable.

    When a first run leaves stations coarse (``stages.join_stations``), registration runs
    again: with ``use_base_poses``, from the poses moved by how far the base reported standing
    from where it stood when calibrated (``fieldapp/recon/arrival.py``; a report beyond
    ``max_base_move_m``/``_deg`` is not used), then with the arrival uncertainty
    ``retry_arrival_factor`` times wider, and wider again by the same factor while stations
    are left, ``retry_widenings`` times at most; the run leaving the fewest stations coarse is
    kept."""

    enabled: bool = True
    retry_arrival_factor: float = Field(default=2.0, ge=1.0)
    """How much wider the arrival uncertainty of each run after the first than the run before
    (1: no such run)."""
    retry_widenings: int = Field(default=3, ge=0)
    """How many runs with a wider prior at most (3: up to 8 times the settings, 24 cm / 12
    degrees with the defaults; beyond that a station's overlaps are too small a part of what
    it sees to be found again, stations 1.6 m apart)."""
    use_base_poses: bool = True
    max_base_move_m: float = Field(default=0.5, gt=0.0)
    max_base_move_deg: float = Field(default=20.0, gt=0.0)
    method: Literal["GICP", "PLANE_ICP"] = "GICP"
    voxel_sizes_m: tuple[float, ...] = (0.1, 0.05, 0.02, 0.008)
    shared_cloud_m: float = Field(default=0.02, ge=0.0)
    correspondence_factor: float = Field(default=5.0, gt=0.0)
    max_correspondence_m: float = Field(default=0.02, gt=0.0)
    max_iterations: int = Field(default=50, ge=1)
    include_soil: bool = True
    min_points: int = Field(default=300, ge=10)
    min_fitness: float = Field(default=0.3, ge=0.0, le=1.0)
    overlap_cell_m: float = Field(default=0.2, gt=0.0)
    overlap_voxel_m: float = Field(default=0.01, gt=0.0)
    min_overlap_m2: float = Field(default=4.0, gt=0.0)
    min_overlap_share: float = Field(default=0.6, gt=0.0, le=1.0)
    """A pair sharing less than ``min_overlap_m2`` is registered still when it shares this share
    of the larger of its two stations' largest overlaps (and ``min_overlap_floor_m2``): a rig
    seeing less ground (a higher, shallower camera) shares less with every neighbour."""
    min_overlap_floor_m2: float = Field(default=1.0, gt=0.0)
    edge_effective_points: float = Field(default=2000.0, gt=0.0)
    edge_noise_m: float = Field(default=0.002, gt=0.0)
    edge_tolerance_m: float = Field(default=0.02, gt=0.0)
    edge_tolerance_deg: float = Field(default=0.8, gt=0.0)
    arrival_sigma_m: float = Field(default=0.03, gt=0.0)
    arrival_sigma_deg: float = Field(default=1.5, gt=0.0)
    level_sigma_deg: float = Field(default=1.0, gt=0.0)
    level_sigma_m: float = Field(default=0.02, gt=0.0)
    guard_sigmas: float = Field(default=4.0, gt=0.0)
    max_uncertainty_m: float = Field(default=0.01, gt=0.0)
    max_uncertainty_deg: float = Field(default=0.4, gt=0.0)


class GridPrior(_Section):
    """The planting grid: plants stand at ``origin + (i * column_spacing, j * row_spacing)``."""

    rows: int = Field(ge=1)
    columns: int = Field(ge=1)
    row_spacing_m: float = Field(gt=0.0)
    column_spacing_m: float = Field(gt=0.0)
    origin_x_m: float = 0.0
    origin_y_m: float = 0.0
    snap_radius_m: float = Field(default=0.15, gt=0.0)


class StemSettings(_Section):
    """Plants from their stems (``fieldapp/recon/stems.py``, ``geodesic.py``): stem feet in
    the lowest ``band_m`` above the local ground, then every point to the stem it is nearest
    to along the plant (a graph of ``graph_voxel_m`` voxels)."""

    enabled: bool = True
    band_m: float = Field(default=0.15, gt=0.0)
    cell_m: float = Field(default=0.01, gt=0.0)
    min_layer_fraction: float = Field(default=0.75, gt=0.0, le=1.0)
    prior_layer_fraction: float = Field(default=0.3, gt=0.0, le=1.0)
    """Near a planting-grid node without a stem, a weaker column is taken as its stem."""
    max_foot_gap_m: float = Field(default=0.05, ge=0.0)
    min_separation_m: float = Field(default=0.12, gt=0.0)
    search_height_m: float = Field(default=0.3, gt=0.0)
    graph_voxel_m: float = Field(default=0.01, gt=0.0)
    seed_radius_m: float = Field(default=0.03, gt=0.0)
    seed_height_m: float = Field(default=0.15, gt=0.0)
    inward_penalty: float = Field(default=15.0, ge=0.0)
    """Extra cost per metre a path runs back towards the stem (plants grow outwards), outside
    the stem's own column (``seed_radius_m``). A neighbour whose leaf a leaf pointing at it
    lies on would otherwise take that leaf's outer part back along it, inwards (3 until
    2026-12-06; 10-25 measured alike, 30 and more lose a seedling beside a tall plant:
    RECONSTRUCTION.md, "Touching canopies", "The inward cost")."""
    bend_penalty_m: float = Field(default=1.0, ge=0.0)
    """Extra cost of a path passing from one surface onto another (a leaf onto the neighbour's
    leaf it touches): up to this for a right angle between the surfaces' normals."""
    sheet_aware: bool = True
    """Where two sheets cross (two leaves in an X), the bend cost is judged against the sheet a
    path is on, not the voxels' normals blurred from both (``geodesic.sheet_graph``); only in
    the parts of the plot where two stems' canopies are joined (nothing runs on a seedling
    plot)."""
    collar_radius_m: float = Field(default=0.0, ge=0.0)
    """A path pays no bend cost while it stays within this (plan view) of its *own* stem and
    no higher than ``collar_height_m`` above the top of its foot: the turn from a stem onto
    its own leaf is free, a neighbour's path turning there still pays (0: off)."""
    collar_height_m: float = Field(default=0.0, ge=0.0)
    junction_radius_m: float = Field(default=0.08, ge=0.0)
    """A stem's own paths may step across gaps within this (plan view) of it: the junction of
    a leaf and its stem, where the cameras saw the stem from one side and the leaf's base not
    whole (``geodesic.Junctions``; 0: off). The leaves' ends that come down to the soil are
    judged before (on the assignment without these steps), so that such an end does not step
    onto the leaves above it."""
    junction_gap_m: float = Field(default=0.04, gt=0.0)
    """The widest gap such a step crosses."""
    junction_penalty_m: float = Field(default=1.0, ge=0.0)
    """What such a step costs on top of its length: as much as the sharpest bend, so that a
    neighbour's leaf passing by the stem stays with the neighbour, whose way along it is
    shorter than this stem's way plus the step."""
    reach_m: float = Field(default=1.0, gt=0.0)
    """How far (plan view) from its stem a plant's leaves may reach."""
    ambiguity_margin_m: float = Field(default=0.15, ge=0.0)
    """A point a second stem reaches within this (along the plant) of the first is ambiguous."""
    flag_ambiguous_share: float = Field(default=0.005, ge=0.0, le=1.0)
    """A plant with more of its points ambiguous than this is flagged in the report."""
    follow_leaves: bool = True
    """The leaves of every plant with an ambiguous point traced as ribbons and followed across
    their contacts (``fieldapp/recon/ribbons.py``): a leaf lying on a neighbour's keeps its
    outer part."""
    leaf_ends: bool = True
    """A stem found where a plant's leaf comes down to the soil is merged into that plant
    (``geodesic.leaf_ends``, by ``leaf_end_share`` and ``leaf_end_slack_m``)."""
    leaf_end_share: float = Field(default=0.9, gt=0.0, le=1.0)
    """A stem whose points above the soil lie, this share of them or more, on the way along the
    plant between its foot and the stem that reaches them second is the end of that plant's
    leaf come down to the soil, and is merged into it (``geodesic.leaf_ends``)."""
    leaf_end_slack_m: float = Field(default=0.2, ge=0.0)
    """A point is on that way when the two feet's paths to it are at most this much longer
    than the shortest way between the feet."""
    leaf_end_share_off_grid: float = Field(default=0.6, gt=0.0, le=1.0)
    """With a planting grid, the share for a stem standing at no node of it (no plant is sown
    there), which is then merged even when it is not much smaller than the plant it would join
    (only never a larger stem into a smaller)."""


class PlantSettings(_Section):
    """Splitting the plant cloud into plants and measuring them."""

    cluster_voxel_m: float = Field(default=0.025, gt=0.0)
    min_points: int = Field(default=200, ge=1)
    min_height_m: float = Field(default=0.03, ge=0.0)
    base_slice_m: float = Field(default=0.02, gt=0.0)
    row_gap_m: float = Field(default=0.1, gt=0.0)
    top_support_points: int = Field(default=3, ge=1)
    top_support_radius_m: float = Field(default=0.006, gt=0.0)
    stems: StemSettings = Field(default_factory=StemSettings)
    grid: GridPrior | None = None


class ReconstructionSettings(_Section):
    """All the reconstruction's parameters (defaults from the paper)."""

    crop: CropSettings = Field(default_factory=CropSettings)
    ground: GroundSettings = Field(default_factory=GroundSettings)
    filters: FilterSettings = Field(default_factory=FilterSettings)
    registration: RegistrationSettings = Field(default_factory=RegistrationSettings)
    plants: PlantSettings = Field(default_factory=PlantSettings)
    threads: int = Field(default=2, ge=1)
