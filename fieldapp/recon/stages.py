"""The reconstruction's stages, each a pure function of plain typed arguments.

A stage returns its result, and the warnings it raised with it (:class:`Staged`); it never
appends to a list it was given and never changes its arguments, so the same arguments give
the same result. :func:`fieldapp.recon.pipeline.reconstruct` calls them in the paper's order,
times them and reports progress between them. Reading a session's images (steps 1-2) and its
plan (the planting grid) is the only input they do.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Collection, Generator, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Generic, Literal, TypeVar

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert, transform_points
from fieldapp.io.calibration import Calibration, T_view0_view, ViewStep
from fieldapp.io.session import Capture, Session
from fieldapp.recon.arrival import BaseMoves, move_coarse
from fieldapp.recon.cloud import Cloud, joined_mixed
from fieldapp.recon.coverage import (
    ViewLimits,
    cut_tops,
    grouped_warnings,
    one_sided,
    station_axes_xy,
    station_poses,
    uncovered,
)
from fieldapp.recon.filters import FilteredStation, filter_station, split_outliers, voxel_mean
from fieldapp.recon.forkmap import ForkedMap
from fieldapp.recon.grid import GridNodes
from fieldapp.recon.guards import COARSE_KEPT, UNRELIABLE
from fieldapp.recon.levelling import T_field_reference_initial, level_stations
from fieldapp.recon.mapframe import (
    in_map_frame,
    map_alignment,
    session_grid,
    turntable_axis_direction,
)
from fieldapp.recon.organ_traits import PlantOrgans, foot_m, measure_organs
from fieldapp.recon.plants import Plant, PlantSearch, search_plants
from fieldapp.recon.register import (
    PairFits,
    RegistrationSteps,
    StationRegistration,
    beyond_arrival,
    register_stations,
)
from fieldapp.recon.scans import StationScan, read_station, turntable_axis_point
from fieldapp.recon.settings import (
    CropSettings,
    FilterSettings,
    GroundSettings,
    PlantSettings,
    RegistrationSettings,
)
from fieldapp.recon.turntable import read_turntable

T = TypeVar("T")


@dataclass(frozen=True)
class Staged(Generic[T]):
    """A stage's result and the warnings it raised, in the order raised."""

    value: T
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class LocalScans:
    """Steps 1-2 done: each usable station's views joined in its view-0 frame, by station.
    For a plant on a turntable (one station), where its field frame is (``T_field_view0``)
    and how its views were placed (``turntable``, for ``report.json``)."""

    scans: dict[int, StationScan]
    T_field_view0: Matrix4 | None = None
    turntable: dict[str, object] | None = None


@dataclass(frozen=True)
class ScanSummary:
    """What ``report.json`` keeps of the scans once their clouds are dropped: how each
    station told plants from soil, its excess-green threshold (colour only), the points kept
    (pixels measured, then by each filter of step 4, summed over the stations), and how many
    views of each station were read."""

    separation: dict[int, str]
    exg_thresholds: dict[int, float]
    kept: dict[str, int]
    turntable: dict[str, object] | None
    views: dict[int, tuple[int, ...]]
    colour_offsets: dict[int, tuple[int, int]] = field(default_factory=dict)
    """Per station whose colour told it (:mod:`fieldapp.recon.colour_offset`), how far
    (dx, dy pixels) its colour was found off its depth and moved back: (0, 0) in place."""


@dataclass(frozen=True)
class Fused:
    """Step 6 done: the plot's plant cloud (overlaps averaged, outliers removed) and soil
    sample (``soil_m``: (M, 3) float64) in the field frame, and the points each step kept."""

    cloud: Cloud
    soil_m: NDArray[np.float64]
    kept: dict[str, int]
    doubtful: Cloud = field(default_factory=Cloud.empty)
    """The points the outlier filters found doubtful (:func:`filters.split_outliers`)."""


@dataclass(frozen=True)
class Placed:
    """The plot in its output frame: the map's x and y when ``T_map_field`` is known (the
    session has map poses), else the levelled field frame."""

    cloud: Cloud
    soil_m: NDArray[np.float64]
    registrations: dict[int, StationRegistration]
    T_map_field: Matrix4 | None
    doubtful: Cloud = field(default_factory=Cloud.empty)
    """The doubtful points (:class:`Fused`), in the same frame: the plants step joins those
    that touch a plant to it, and its cloud then replaces ``cloud`` (:func:`find_plants`)."""


@dataclass(frozen=True)
class GridPrior:
    """The session's planting grid in the output frame and how many plants it expects
    (``None`` for both without a usable grid)."""

    nodes: GridNodes | None
    expected: int | None


def missing_captures(missing: list[tuple[int, int]]) -> tuple[str, ...]:
    """One warning listing the (station, view) captures the session lacks, if any."""
    if not missing:
        return ()
    listed = ", ".join(f"s{s} v{v}" for s, v in missing)
    return (f"{len(missing)} captures missing: {listed}",)


def station_scan(
    session: Session,
    station: int,
    captures: list[Capture],
    rays: NDArray[np.float64],
    crop: CropSettings,
    exg_threshold: float | Literal["otsu"],
    soil_pixel_stride: int,
    threads: int = 1,
) -> Staged[StationScan | None]:
    """Steps 1-2 for one station: depth to points through the ray table ``rays`` ((H, W, 3)
    float64), early excess-green filtering, every view into view 0 by the view step (Eq. 9);
    ``None`` when no capture could be read. Its frames are read on ``threads`` threads."""
    scan, warnings = read_station(
        session, station, captures, crop, exg_threshold, soil_pixel_stride, rays, threads
    )
    return Staged(scan, tuple(warnings))


def calibrated_scans(
    read: dict[int, Staged[StationScan | None]], calibrated: Collection[int]
) -> Staged[LocalScans]:
    """Steps 1-2 for the plot: the stations read that the station calibration places
    (``calibrated``); the warnings station by station."""
    scans: dict[int, StationScan] = {}
    warnings: list[str] = []
    for station, staged in read.items():
        warnings.extend(staged.warnings)
        if staged.value is not None and station not in calibrated:
            warnings.append(f"station {station} has no to_reference calibration: skipped")
        elif staged.value is not None:
            scans[station] = staged.value
    return Staged(LocalScans(scans), tuple(warnings))


def turntable_scan(
    session: Session, crop: CropSettings, top_m: float, refine: bool
) -> Staged[LocalScans]:
    """Steps 1-2 for a plant turning before a fixed camera: the room masked, the views placed
    about the table's axis (refined by ICP when ``refine`` and the view step is nominal)."""
    table, warnings = read_turntable(session, crop, top_m, refine)
    if table is None:
        return Staged(LocalScans({}), tuple(warnings))
    scans = {table.scan.station: table.scan}
    return Staged(LocalScans(scans, table.T_field_view0, table.report), tuple(warnings))


def anchor(reference: int, scans: Collection[int], to_reference: dict[int, Matrix4]) -> Staged[int]:
    """The station anchoring the plot: the calibrated ``reference``, or the read station
    (``scans``) nearest to it when it has no usable capture."""
    if reference in scans:
        return Staged(reference)
    nearest = min(scans, key=lambda s: (float(np.linalg.norm(to_reference[s][:3, 3])), s))
    missing = f"reference station {reference} has no usable capture"
    return Staged(nearest, (f"{missing}: station {nearest} anchors the plot",))


def level(
    local: LocalScans, calibration: Calibration, reference: int, ground: GroundSettings
) -> Staged[dict[int, Matrix4]]:
    """Step 3: each station's ``T_field_station``. Placed coarsely (the turntable's own
    frame; else the ground calibration, or the reference station's own ground, and the
    station calibration), then corrected onto the ground it sees."""
    if local.T_field_view0 is not None:
        coarse = {reference: local.T_field_view0}
    else:
        to_reference = calibration.stations.to_reference if calibration.stations else {}
        T_field_ref = T_field_reference_initial(calibration, local.scans[reference], ground)
        coarse = {s: T_field_ref @ to_reference[s] for s in local.scans}
    levelled, warnings = level_stations(local.scans, coarse, ground)
    return Staged(levelled, tuple(warnings))


def starting_poses(
    T_field_levelled: dict[int, Matrix4],
    reference: int,
    view_step: ViewStep,
    moves: BaseMoves | None,
    settings: RegistrationSettings,
) -> Staged[dict[int, Matrix4]]:
    """Where a later registration run starts each station (:func:`join_stations`): its
    levelled pose, moved by where the base reported it stopped (``recon/arrival.py``) when
    ``moves`` are given and ``settings.use_base_poses``. The stations' filtered points stay as
    levelling placed them (their voxel means unchanged): :func:`join_stations` maps each
    correction back onto the levelled pose."""
    if moves is None or not settings.use_base_poses or len(T_field_levelled) < 2:
        return Staged(dict(T_field_levelled))
    moved = move_coarse(
        T_field_levelled,
        reference,
        moves,
        turntable_axis_point(view_step.matrix, view_step.views_per_turn),
        turntable_axis_direction(view_step.matrix),
        settings,
    )
    return Staged(moved.T_field_station, moved.warnings)


def filter_plants(
    scan: StationScan, T_field_station: Matrix4, filters: FilterSettings, ground: GroundSettings
) -> FilteredStation:
    """Step 4 for one station, levelled: pass-through above the ground (or the plants
    standing clear of it, by geometry), voxel means; a sparse soil sample."""
    return filter_station(
        scan.green.transformed(T_field_station),
        scan.soil.transformed(T_field_station),
        filters,
        ground.soil_band_m,
        ground.soil_voxel_m,
        scan.separation.by_geometry,
        None
        if scan.steady is None
        else (
            scan.steady[0].transformed(T_field_station),
            scan.steady[1].transformed(T_field_station),
        ),
        None if scan.continued is None else scan.continued.transformed(T_field_station),
    )


def summarise(
    local: Staged[LocalScans], filtered: dict[int, FilteredStation]
) -> Staged[ScanSummary]:
    """What the report keeps of steps 1-4, with the warnings of steps 1-2."""
    scans = local.value.scans.values()
    measured = {"measured_pixels": sum(scan.measured_pixels for scan in scans)}
    summary = ScanSummary(
        separation={scan.station: scan.separation.describe() for scan in scans},
        exg_thresholds={
            scan.station: scan.exg_threshold for scan in scans if not scan.separation.by_geometry
        },
        kept=measured | _kept_by_filters(filtered),
        turntable=local.value.turntable,
        views={scan.station: tuple(scan.views) for scan in scans},
        colour_offsets={
            scan.station: (scan.colour_offset.dx_px, scan.colour_offset.dy_px)
            for scan in scans
            if scan.colour_offset is not None
        },
    )
    return Staged(summary, local.warnings + _colour_offset_warnings(scans))


def _colour_offset_warnings(scans: Iterable[StationScan]) -> tuple[str, ...]:
    """One warning per offset at which stations' colour was found off their depth: the
    sensor's registration wants calibrating, and the operator should know the colour was
    moved."""
    by_offset: dict[tuple[int, int], list[StationScan]] = defaultdict(list)
    for scan in scans:
        offset = scan.colour_offset
        if offset is not None and offset.moved:
            by_offset[offset.dx_px, offset.dy_px].append(scan)
    warnings = []
    for moved in by_offset.values():
        offset, stations = moved[0].colour_offset, [scan.station for scan in moved]
        assert offset is not None
        named = f"station{'s' if len(stations) > 1 else ''} {', '.join(map(str, stations))}"
        border = (
            " (as far as looked for: the registration may be further off)"
            if offset.at_search_border
            else ""
        )
        warnings.append(
            f"{named}: the colour images lie {offset.describe()} of the depth{border}; moved "
            "back onto it (to where the colour's edges meet the depth's). The sensor's "
            "colour-to-depth registration wants calibrating"
        )
    return tuple(warnings)


def join_stations(
    filtered: dict[int, FilteredStation],
    T_field_levelled: dict[int, Matrix4],
    view_step: ViewStep,
    reference: int,
    settings: RegistrationSettings,
    threads: int,
    moves: BaseMoves | None = None,
    overlap_radius_m: float | None = None,
) -> Generator[tuple[float, str], None, Staged[dict[int, StationRegistration]]]:
    """Step 5: one pose graph of every overlapping pair, the levelled poses as its prior;
    yields (fraction done, message) per pair registered. A warning per station whose
    refinement was refused or is unreliable. Each registration's ``T_correction`` maps the
    station's levelled placement (where its filtered points are) onto the final one.

    When the first run leaves stations coarse or unreliable (:func:`beyond_arrival`: for any
    reason but a correction that does not make its overlaps agree better, a fit in the wrong
    place that nothing here would mend), the base probably erred more than the settings say,
    and registration runs again (:func:`_later_runs`): from the levelled poses moved by where
    the base reported it stopped (``moves``, :func:`starting_poses`), then, while stations are
    still left, with the arrival uncertainty ``retry_arrival_factor`` times wider each run
    (``retry_widenings`` runs at most); a run takes the pair fits of the runs before it where
    a pair starts from the same poses (:class:`~fieldapp.recon.register.PairFits`). The run
    leaving the fewest stations coarse is kept (the first on a tie), with a warning saying how
    it was placed. Every run keeps its guards. A
    plot registered the first time is registered exactly as before: on touching canopies a
    millimetre of registration decides some leaf tips (RECONSTRUCTION.md, "Touching
    canopies"), so the first run does not change with the reports."""
    points = _registration_points(
        filtered, T_field_levelled, settings.include_soil, view_step, overlap_radius_m
    )
    axis = turntable_axis_point(view_step.matrix, view_step.views_per_turn)
    known = PairFits()  # a run from the same starting poses takes the fits made before
    registrations = yield from register_stations(
        points, T_field_levelled, axis, reference, settings, threads, known
    )
    first, start, how_placed = _kept_coarse(registrations), T_field_levelled, ""
    moved: Staged[dict[int, Matrix4]] = Staged(T_field_levelled)
    if settings.enabled and any(map(beyond_arrival, registrations.values())):
        moved = starting_poses(T_field_levelled, reference, view_step, moves, settings)
    for run_start, run_settings, how in _later_runs(settings, T_field_levelled, moved.value):
        if not settings.enabled or not any(map(beyond_arrival, registrations.values())):
            break
        again = yield from _done_already(
            register_stations(points, run_start, axis, reference, run_settings, threads, known),
            f"registering again {how}: ",
        )
        if len(_kept_coarse(again)) < len(_kept_coarse(registrations)):
            registrations, start, how_placed = again, run_start, how
    notes: tuple[str, ...] = ()
    if how_placed:
        refined = len(first) - len(_kept_coarse(registrations))
        kept = "its coarse pose" if len(first) == 1 else "coarse poses"
        outcome = "it is refined" if len(first) == 1 else f"{refined} of them are refined"
        notes = (
            f"registration: with the arrival uncertainty of the settings ({_sigmas(settings)}) "
            f"{_listed(first)} kept at {kept}; registered again {how_placed}, {outcome}. The "
            "base errs more than registration.arrival_sigma_m / _deg say: set them to match it",
        )
    registrations = {  # each correction from where the station's filtered points are
        s: replace(r, T_correction=r.T_correction @ start[s] @ invert(T_field_levelled[s]))
        for s, r in registrations.items()
    }
    warnings = tuple(
        f"station {station} {r.verdict}: {r.message}"
        for station, r in registrations.items()
        if r.verdict in (COARSE_KEPT, UNRELIABLE) and settings.enabled
    )
    return Staged(registrations, notes + moved.warnings + warnings)


def _later_runs(
    settings: RegistrationSettings,
    T_field_levelled: dict[int, Matrix4],
    T_field_moved: dict[int, Matrix4],
) -> list[tuple[dict[int, Matrix4], RegistrationSettings, str]]:
    """The registrations to try after the first, in order: (starting poses, settings, how
    they differ): from the moved poses when any station moved, then with the arrival
    uncertainty ``retry_arrival_factor`` times wider, and wider again by the same factor,
    ``retry_widenings`` times (the caller stops when no station is left)."""
    runs: list[tuple[dict[int, Matrix4], RegistrationSettings, str]] = []
    moved, from_reports = T_field_levelled, ""
    if any(not np.array_equal(T_field_moved[s], T_field_levelled[s]) for s in T_field_levelled):
        moved, from_reports = T_field_moved, "from where the base reported each stop"
        runs.append((moved, settings, from_reports))
    for wider in _wider_priors(settings):
        how = " and ".join(filter(None, [from_reports, f"with {_sigmas(wider)}"]))
        runs.append((moved, wider, how))
    return runs


def _wider_priors(settings: RegistrationSettings) -> list[RegistrationSettings]:
    """``settings`` with the arrival uncertainty widened by ``retry_arrival_factor`` again and
    again, ``retry_widenings`` times."""
    factor = settings.retry_arrival_factor
    if factor <= 1.0:
        return []
    return [
        settings.model_copy(
            update={
                "arrival_sigma_m": factor**k * settings.arrival_sigma_m,
                "arrival_sigma_deg": factor**k * settings.arrival_sigma_deg,
            }
        )
        for k in range(1, settings.retry_widenings + 1)
    ]


def _done_already(steps: RegistrationSteps, prefix: str) -> RegistrationSteps:
    """``steps`` with every progress event at 1.0 (the stage's bar has run once already)."""
    while True:
        try:
            _, message = next(steps)
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]
        yield 1.0, prefix + message


def _kept_coarse(registrations: dict[int, StationRegistration]) -> list[int]:
    return [s for s, r in registrations.items() if r.verdict in (COARSE_KEPT, UNRELIABLE)]


def _listed(stations: list[int]) -> str:
    if len(stations) == 1:
        return f"station {stations[0]} was"
    return f"stations {', '.join(map(str, stations))} were"


def _sigmas(settings: RegistrationSettings) -> str:
    return f"{100 * settings.arrival_sigma_m:g} cm / {settings.arrival_sigma_deg:g} deg"


def _registration_points(
    filtered: dict[int, FilteredStation],
    T_field_levelled: dict[int, Matrix4],
    include_soil: bool,
    view_step: ViewStep,
    radius_m: float | None,
) -> dict[int, NDArray[np.float64]]:
    """Per station, the (N, 3) points ICP aligns (plants, and soil when ``include_soil``, at
    their blocks' median depths where read so: ``FilteredStation.registration_points``), in
    its view-0 frame; with ``radius_m``, only those within it of one of the station's views'
    optical centres (``view_step``; :func:`~fieldapp.recon.backproject.overlap_radius`; None:
    all of them)."""
    points = {
        station: transform_points(
            invert(T_field_levelled[station]), result.registration_points(include_soil)
        )
        for station, result in filtered.items()
    }
    if radius_m is None:
        return points
    centres = np.array(
        [view_step.T_view0_view(view)[:3, 3] for view in range(view_step.views_per_turn)]
    )
    return {station: _within(p, centres, radius_m) for station, p in points.items()}


def _within(
    points_m: NDArray[np.float64], centres_m: NDArray[np.float64], radius_m: float
) -> NDArray[np.float64]:
    """The (N, 3) ``points_m`` within ``radius_m`` of one of the (V, 3) ``centres_m``."""
    near = np.zeros(len(points_m), dtype=bool)
    for centre in centres_m:
        near |= np.einsum("ij,ij->i", points_m - centre, points_m - centre) <= radius_m**2
    kept: NDArray[np.float64] = points_m[near]
    return kept


def fuse(
    filtered: dict[int, FilteredStation],
    registrations: dict[int, StationRegistration],
    filters: FilterSettings,
    threads: int,
) -> Fused:
    """Step 6: one plant cloud of the plot, overlaps averaged; outliers removed where every
    station's view of a leaf is together (statistical, then radius)."""
    fused, soil_m = _joined(filtered, registrations, filters.voxel_size_m)
    cloud, doubtful, outlier_counts = split_outliers(fused, filters, threads)
    continued = _continued(filtered, registrations, filters.voxel_size_m)
    if len(continued):
        # apart from the plants until they are found: they join the one they continue as the
        # doubtful points do (plants._with_loose), and move no other point
        doubtful = Cloud.concatenate([doubtful, continued])
    return Fused(cloud, soil_m, {"fused": len(fused)} | outlier_counts, doubtful)


def _continued(
    filtered: dict[int, FilteredStation],
    registrations: dict[int, StationRegistration],
    voxel_m: float,
) -> Cloud:
    """Every station's points of the leaves' surfaces continued past their green
    (``FilteredStation.continued``) in the plot's frame, averaged in ``voxel_m`` voxels."""
    moved = [
        f.continued.transformed(registrations[station].T_correction)
        for station, f in filtered.items()
        if len(f.continued)
    ]
    return voxel_mean(Cloud.concatenate(moved), voxel_m) if moved else Cloud.empty()


def _joined(
    filtered: dict[int, FilteredStation],
    registrations: dict[int, StationRegistration],
    voxel_m: float,
) -> tuple[Cloud, NDArray[np.float64]]:
    """Every station's plants in the plot's frame, averaged in ``voxel_m`` voxels, and the
    soil samples ((M, 3) float64). Its own function so that the stations' moved copies are
    freed before the outlier removal's neighbour search, the pipeline's largest."""
    total = sum(len(f.plants) for f in filtered.values())
    mixed = joined_mixed([f.plants for f in filtered.values()])
    plants = Cloud(np.empty((total, 3)), np.empty((total, 3), dtype=np.uint8), mixed)
    at = 0
    for station, f in filtered.items():  # moved into place: no second copy of the plot
        rows = slice(at, at + len(f.plants))
        plants.points[rows] = transform_points(registrations[station].T_correction, f.plants.points)
        plants.colors[rows] = f.plants.colors
        at = rows.stop
    soil = [transform_points(registrations[s].T_correction, f.soil_m) for s, f in filtered.items()]
    return voxel_mean(plants, voxel_m), np.concatenate(soil)


def _kept_by_filters(filtered: dict[int, FilteredStation]) -> dict[str, int]:
    """The points each per-station filter kept, summed over the stations."""
    total: dict[str, int] = {}
    for result in filtered.values():
        for name, count in result.kept.items():
            total[name] = total.get(name, 0) + count
    return total


def on_map(
    fused: Fused,
    registrations: dict[int, StationRegistration],
    map_poses: dict[int, tuple[float, float, float]],
    view_step: ViewStep,
) -> Placed:
    """The plot turned and shifted onto the base's map (``map_poses``: per station, x_m,
    y_m, yaw_deg) by where each station's turntable axis stands; unchanged without poses."""
    T_map_field = map_alignment(
        map_poses,
        {s: r.T_field_station for s, r in registrations.items()},
        turntable_axis_point(view_step.matrix, view_step.views_per_turn),
        turntable_axis_direction(view_step.matrix),
    )
    if T_map_field is None:
        return Placed(fused.cloud, fused.soil_m, registrations, None, fused.doubtful)
    cloud, soil_m, placed = in_map_frame(T_map_field, fused.cloud, fused.soil_m, registrations)
    return Placed(cloud, soil_m, placed, T_map_field, fused.doubtful.transformed(T_map_field))


def planting_grid(session: Session, T_map_field: Matrix4 | None) -> Staged[GridPrior]:
    """The session plan's planting grid in the output frame, when it can be placed."""
    warnings: list[str] = []  # mapframe.session_grid reports into a list it is handed
    nodes, expected = session_grid(session, T_map_field, warnings)
    return Staged(GridPrior(nodes, expected), tuple(warnings))


def coverage(
    placed: Placed,
    plants: list[Plant],
    calibration: Calibration,
    reference: int,
    scanned: ScanSummary,
    crop: CropSettings,
    pass_through_max_m: float,
) -> Staged[dict[int, tuple[str, ...]]]:
    """Warns of the plants the captures did not cover as planned (``recon/coverage.py``): the
    station nearest each has no usable capture or turned through fewer views than a turn; and
    of those whose highest point lies where the views (the calibration's camera, cropped to
    ``crop``) stop seeing or at the filters' ``pass_through_max_m``. Nothing for a plant on a
    turntable (one station, placed by the table). The value: each such plant's cautions, for
    its entry in ``report.json``."""
    view_step, stations = calibration.view_step, calibration.stations
    if scanned.turntable is not None or view_step is None or stations is None:
        return Staged({})
    to_reference, camera = stations.to_reference, calibration.depth_camera
    T_field_station = {s: r.T_field_station for s, r in placed.registrations.items()}
    stations_xy = station_axes_xy(
        T_field_station,
        to_reference,
        reference,
        turntable_axis_point(view_step.matrix, view_step.views_per_turn),
    )
    plants_xy = {p.id: np.array([p.traits.x_m, p.traits.y_m]) for p in plants}
    views = {s: len(v) for s, v in scanned.views.items()}
    turn = view_step.views_per_turn
    cautions = list(uncovered(plants_xy, stations_xy, views, turn).items())

    def cameras(poses: Mapping[int, Matrix4], views: Mapping[int, Sequence[int]]) -> NDArray[Any]:
        """(V, 4, 4) the poses of the ``views`` (station -> view indices) of the stations
        in ``poses``."""
        shots = [
            poses[s] @ T_view0_view(view_step.matrix, view)
            for s, indices in views.items()
            if s in poses
            for view in indices
        ]
        return np.array(shots).reshape(-1, 4, 4)

    read = cameras(T_field_station, scanned.views)
    planned = cameras(
        station_poses(T_field_station, to_reference, reference),
        {s: range(turn) for s in to_reference},
    )
    flagged = {plant for plant, _ in cautions}
    centres = {
        p.id: np.array([p.traits.x_m, p.traits.y_m, _mid_height_m(p)])
        for p in plants
        if p.id not in flagged
    }
    limits = ViewLimits(camera, crop.radius_m, crop.min_depth_m)
    cautions += one_sided(centres, planned, read, limits).items()
    tops = {p.id: p.cloud.points[int(np.argmax(p.cloud.points[:, 2]))] for p in plants}
    cautions += cut_tops(tops, read, limits, pass_through_max_m).items()
    notes: dict[int, tuple[str, ...]] = {}
    for plant, caution in sorted(cautions, key=lambda item: item[0]):
        notes[plant] = (*notes.get(plant, ()), caution.note())
    return Staged(notes, tuple(grouped_warnings(cautions, turn)))


def _mid_height_m(plant: Plant) -> float:
    """Halfway up ``plant``'s points (output frame)."""
    z = plant.cloud.points[:, 2]
    return float(z.min() + z.max()) / 2.0


def plant_settings(
    plants: PlantSettings, filters: FilterSettings, scans: Iterable[StationScan]
) -> PlantSettings:
    """The plants step's settings for these stations: where every station's plants were told
    from the soil by geometry (no colour), no plant is shorter than the geometry split's bar
    (``filters.geometry_plant_min_m``). The split keeps a clod that touches a low leaf (it is
    connected to something tall); the plants step may then cut it from the leaf, and without
    colour a clod standing alone is what the split drops (a simulated 3 x 3 plot, 40 clods a
    square metre, depth-only: a 3.9 cm "plant" of 404 points off the planting grid)."""
    scans = list(scans)
    if not scans or not all(scan.separation.by_geometry for scan in scans):
        return plants
    lowest = max(plants.min_height_m, filters.geometry_plant_min_m)
    return plants.model_copy(update={"min_height_m": lowest})


def find_plants(
    placed: Placed,
    settings: PlantSettings,
    ground_radius_m: float,
    grid: GridNodes | None,
) -> Staged[PlantSearch]:
    """Step 7-8: plants from their stems (density clusters where no stem is seen), the
    planting grid as a prior, each measured (height, maximum width). Warns of plants that may
    hold a neighbour's points, grid cells left empty, plants off the grid, and no plant. The
    doubtful points join the plants they touch (``PlantSearch.cloud``: the plot's cloud
    after)."""
    search = search_plants(
        placed.cloud, placed.soil_m, settings, ground_radius_m, grid, placed.doubtful
    )
    warnings = search.warnings(settings.stems.flag_ambiguous_share)
    return Staged(search, (*warnings, *(() if search.plants else ("no plant found",))))


def organs(plants: list[Plant], threads: int = 1) -> dict[int, PlantOrgans]:
    """Beyond the paper: each plant's organs (stem, whorl, each leaf) and their traits; the
    plants shared by this process and a forked worker (:mod:`forkmap`) with ``threads`` >= 2."""
    jobs = [(p.cloud.points, foot_m(p.traits)) for p in plants]
    with ForkedMap(threads) as runner:
        measured = list(runner.map(_measure_organs, jobs))
    return {p.id: organs for p, organs in zip(plants, measured, strict=True)}


def _measure_organs(job: tuple[NDArray[np.float64], NDArray[np.float64]]) -> PlantOrgans:
    """:func:`measure_organs` of one plant's ``(points, foot)``, module level for a worker."""
    return measure_organs(*job)
