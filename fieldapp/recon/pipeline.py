"""The reconstruction, step by step as the paper describes it.

``reconstruct(session, settings)`` is a generator: it yields :class:`Progress` events between
steps (closing it cancels the work there) and returns a :class:`Reconstruction`.
:func:`run_reconstruction` is the blocking form. Each step is a pure function of
:mod:`fieldapp.recon.stages`; this module only calls them in order, times them and reports
progress.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Generator
from dataclasses import dataclass, replace
from typing import TypeVar

from devices.geometry import Matrix4
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Stations, ViewStep
from fieldapp.io.session import Session
from fieldapp.recon import stages
from fieldapp.recon.arrival import BaseMoves, base_moves
from fieldapp.recon.backproject import overlap_radius, ray_table, rig_crop
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.early import EarlyStations, StationRead, read_arguments
from fieldapp.recon.filters import FilteredStation
from fieldapp.recon.levelling import T_field_reference_initial, level_stations
from fieldapp.recon.mapframe import station_map_poses
from fieldapp.recon.organ_traits import PlantOrgans
from fieldapp.recon.plants import MEETS_NOTE, PlantSearch
from fieldapp.recon.progress import Progress, StageTimer, progress
from fieldapp.recon.register import StationRegistration
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.scans import (
    StationScan,
    captures_by_station,
    carries_plant,
    return_freed_memory,
)
from fieldapp.recon.settings import ReconstructionSettings

log = logging.getLogger(__name__)

K = TypeVar("K")
V = TypeVar("V")
R = TypeVar("R")


class NothingUsable(FieldappError):
    """The session holds nothing that can be reconstructed."""


def reconstruct(
    session: Session, settings: ReconstructionSettings, early: EarlyStations | None = None
) -> Generator[Progress, None, Reconstruction]:
    """Reconstruct ``session``: local reconstruction of each station, levelling, plant
    filtering, global registration, plants and their traits, organs and theirs. ``early``: a
    reader of the stations started before the pipeline's modules were imported
    (:func:`fieldapp.recon.early.start_reading`), closed here in any case."""
    try:
        timer, (view_step, stations) = StageTimer(), _joinable(session)
        # 1-2. Depth to points, every view of a station into its view 0 (Eq. 9); steps 3-4
        # for each station as soon as it is read (_Streaming), its green points dropped then.
        stream = None if carries_plant(session) else _Streaming(session, settings, timer)
        local = yield from _local_reconstruction(session, settings, stations, timer, early, stream)
    finally:
        if early is not None:
            early.close()
    reference = stages.anchor(stations.reference, local.value.scans, stations.to_reference)
    # 3. Levelling: coarse placement by the pre-calibration, each station on its own ground.
    # 4. Plant filtering per station: pass-through above the ground, voxel means.
    if stream is not None:
        levelled, filtered = stream.placed(reference.value, local.value.scans)
        del stream  # it holds the stations' clouds too
    else:
        levelled, filtered = _on_turntable(session, local.value, reference.value, settings, timer)
    yield progress("levelling", 1.0, "stations levelled")
    for index, station in enumerate(filtered):
        yield progress("filtering", (index + 1) / len(filtered), f"station {station} filtered")
    scanned = stages.summarise(local, filtered)
    plant_settings = stages.plant_settings(
        settings.plants, settings.filters, local.value.scans.values()
    )
    del local  # the station clouds are no longer needed
    # 5. Stations joined: one pose graph of every overlap, the levelled poses as its prior.
    joined = yield from _registration(
        filtered,
        levelled.value,
        base_moves(session),
        view_step,
        reference.value,
        settings,
        timer,
        overlap_radius(settings.crop, session.calibration),
    )
    # 6. One cloud of the plot; outliers removed where every station's view is together.
    with timer.stage("outlier removal"):
        fused = stages.fuse(filtered, joined.value, settings.filters, settings.threads)
    # The stations' clouds are in the fused one now; what registration and fusion freed is
    # given back before the plants step, the largest (a 6 x 6 touching plot: 250 MB).
    del filtered
    return_freed_memory()
    yield progress("plants", 0.5, "outliers removed")
    # 7-8. Plants from their stems and their traits, in plot coordinates (the map's x and y).
    with timer.stage("plants"):
        placed = stages.on_map(fused, joined.value, station_map_poses(session), view_step)
        grid = stages.planting_grid(session, placed.T_map_field)
        ground_radius_m = settings.ground.local_ground_radius_m
        found = stages.find_plants(placed, plant_settings, ground_radius_m, grid.value.nodes)
        if found.value.cloud is not None:  # with the doubtful points that joined a plant
            placed = replace(placed, cloud=found.value.cloud, doubtful=Cloud.empty())
        crop = rig_crop(settings.crop, session.calibration)
        seen = (session.calibration, reference.value, scanned.value, crop)
        covered = stages.coverage(
            placed, found.value.plants, *seen, settings.filters.pass_through_max_m
        )
    # Beyond the paper: each plant's organs (stem, whorl, each leaf) and their traits.
    with timer.stage("organs"):
        organs = stages.organs(found.value.plants, settings.threads)
    yield progress("traits", 1.0, f"{len(found.value.plants)} plants")
    warnings = [
        *stages.missing_captures(session.missing()),
        *(
            w
            for step in (scanned, reference, levelled, joined, grid, found, covered)
            for w in step.warnings
        ),
    ]
    plot = _Plot(
        reference.value,
        scanned.value,
        fused,
        placed,
        grid.value,
        found.value,
        organs,
        _with_meets(covered.value, found.value.meets),
        crop.radius_m,
    )
    return _result(session.id, plot, settings, timer, warnings)


def run_reconstruction(
    session: Session,
    settings: ReconstructionSettings,
    on_progress: Callable[[Progress], None] | None = None,
    early: EarlyStations | None = None,
) -> Reconstruction:
    """Run :func:`reconstruct` to the end, passing each progress event to ``on_progress``."""
    steps = reconstruct(session, settings, early)
    while True:
        try:
            event = next(steps)
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]
        if on_progress is not None:
            on_progress(event)


def _timed_steps(
    timer: StageTimer, stage: str, steps: Generator[tuple[float, str], None, R]
) -> Generator[Progress, None, R]:
    """Run ``steps`` (fraction done, message), timing them under ``stage``; returns their value."""
    while True:
        try:
            with timer.stage(stage):
                fraction, message = next(steps)
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]
        yield progress(stage, fraction, message)


def _joinable(session: Session) -> tuple[ViewStep, Stations]:
    """The calibration's view step and stations; :class:`NothingUsable` without them."""
    calibration = session.calibration
    if calibration.view_step is None or calibration.stations is None:
        raise NothingUsable(f"{session.folder}: the calibration cannot join views and stations")
    return calibration.view_step, calibration.stations


def _local_reconstruction(
    session: Session,
    settings: ReconstructionSettings,
    stations: Stations,
    timer: StageTimer,
    early: EarlyStations | None,
    stream: _Streaming | None,
) -> Generator[Progress, None, stages.Staged[stages.LocalScans]]:
    """Steps 1-2, a progress event per station (one for a plant on a turntable);
    :class:`NothingUsable` when no capture could be read. Each station read goes through
    ``stream`` when given."""
    if carries_plant(session):  # camera fixed, plant turning: the room masked
        with timer.stage("local reconstruction"):
            crop, top_m = settings.crop, settings.filters.pass_through_max_m
            local = stages.turntable_scan(session, crop, top_m, settings.registration.enabled)
        yield progress("local reconstruction", 1.0, "turntable views joined")
    elif early is not None and early.serves(session, read_arguments(settings, session.calibration)):
        local = yield from _early_scans(early, settings, stations, timer, stream)
    else:
        local = yield from _station_scans(session, settings, stations, timer, stream)
    if not local.value.scans:
        raise NothingUsable(f"{session.folder}: no capture could be read{_why(local.warnings)}")
    return local


def _why(warnings: tuple[str, ...], shown: int = 2) -> str:
    """The first of the reasons captures were skipped, for an error that ends the run (its
    warnings are never printed): ": station 1 view 0 skipped: ...; and 71 more"."""
    if not warnings:
        return ""
    more = f"; and {len(warnings) - shown} more" if len(warnings) > shown else ""
    return ": " + "; ".join(warnings[:shown]) + more


def _station_scans(
    session: Session,
    settings: ReconstructionSettings,
    stations: Stations,
    timer: StageTimer,
    stream: _Streaming | None,
) -> Generator[Progress, None, stages.Staged[stages.LocalScans]]:
    """Steps 1-2 station by station, a progress event after each."""
    keep = stream.take if stream is not None else None
    with timer.stage("local reconstruction"):
        rays = ray_table(session.calibration.depth_camera.intrinsics())
        grouped = captures_by_station(session)
        arguments = read_arguments(settings, session.calibration)  # crop scaled to the rig
    read = yield from _per_station(
        timer,
        "local reconstruction",
        grouped,
        lambda station, captures: _kept(
            stages.station_scan(
                session,
                station,
                captures,
                rays,
                arguments.crop,
                arguments.exg_threshold,
                arguments.soil_pixel_stride,
                settings.threads,
            ),
            keep,
        ),
        lambda index, _: f"station {index + 1} of {len(grouped)}",
    )
    return stages.calibrated_scans(read, stations.to_reference)


def _early_scans(
    early: EarlyStations,
    settings: ReconstructionSettings,
    stations: Stations,
    timer: StageTimer,
    stream: _Streaming | None,
) -> Generator[Progress, None, stages.Staged[stages.LocalScans]]:
    """Steps 1-2 shared with the early reader, a progress event per station as it is done."""
    reads, count = early.read(settings.threads, stream.take if stream else None), 0
    while True:
        try:
            with timer.stage("local reconstruction"):
                next(reads)
        except StopIteration as done:
            read: dict[int, StationRead] = done.value
            break
        count += 1
        message = f"station {count} of {early.station_count}"
        yield progress("local reconstruction", count / early.station_count, message)
    staged = {station: stages.Staged(scan, tuple(w)) for station, (scan, w) in read.items()}
    return stages.calibrated_scans(staged, stations.to_reference)


def _registration(
    filtered: dict[int, FilteredStation],
    T_field_levelled: dict[int, Matrix4],
    moves: BaseMoves | None,
    view_step: ViewStep,
    reference: int,
    settings: ReconstructionSettings,
    timer: StageTimer,
    overlap_radius_m: float | None,
) -> Generator[Progress, None, stages.Staged[dict[int, StationRegistration]]]:
    """Step 5, a progress event per pair of stations registered and one when all are placed."""
    steps = stages.join_stations(
        filtered,
        T_field_levelled,
        view_step,
        reference,
        settings.registration,
        settings.threads,
        moves,
        overlap_radius_m,
    )
    joined = yield from _timed_steps(timer, "registration", steps)
    yield progress("registration", 1.0, f"{len(joined.value)} stations placed")
    return joined


def _kept(
    read: stages.Staged[StationScan | None], keep: Callable[[StationScan], StationScan] | None
) -> stages.Staged[StationScan | None]:
    """What is kept of a station read: its scan passed through ``keep`` when given."""
    if read.value is None or keep is None:
        return read
    return stages.Staged(keep(read.value), read.warnings)


def _on_turntable(
    session: Session,
    local: stages.LocalScans,
    reference: int,
    settings: ReconstructionSettings,
    timer: StageTimer,
) -> tuple[stages.Staged[dict[int, Matrix4]], dict[int, FilteredStation]]:
    """Steps 3-4 for a plant on a turntable: its one station placed by the table's axis."""
    with timer.stage("levelling"):
        levelled = stages.level(local, session.calibration, reference, settings.ground)
    with timer.stage("filtering"):
        filtered = {
            s: stages.filter_plants(scan, levelled.value[s], settings.filters, settings.ground)
            for s, scan in local.scans.items()
        }
    return levelled, filtered


class _Streaming:
    """Steps 3-4 for each station as soon as it is read (:meth:`take`): levelled on its own
    ground and filtered, then kept without its green points, so that memory does not grow
    with every station's full cloud until all are read (a depth-only session's "green"
    points are every point it measured: 30 MB a station).

    A station is placed once the field frame is known: at once when the calibration has a
    ground transform, else when the reference station, whose ground gives it, is read. The
    stations read before it wait whole until then; when the reference has no usable
    capture, until the end (:meth:`placed`), where the station anchoring the plot instead
    gives it. Each station is levelled and filtered exactly as all together would be."""

    def __init__(self, session: Session, settings: ReconstructionSettings, timer: StageTimer):
        self._calibration = session.calibration
        stations = session.calibration.stations
        self._to_reference = stations.to_reference if stations is not None else {}
        self._reference = stations.reference if stations is not None else None
        ground = session.calibration.ground
        self._T_field_ref: Matrix4 | None = ground.matrix if ground is not None else None
        self._settings = settings
        self._timer = timer
        self._waiting: dict[int, StationScan] = {}
        self._levelled: dict[int, stages.Staged[Matrix4]] = {}
        self._filtered: dict[int, FilteredStation] = {}

    def take(self, scan: StationScan) -> StationScan:
        """``scan`` without its green points (nor their steady copy), levelled and filtered now
        or when it can be."""
        if scan.station not in self._to_reference:  # skipped with a warning: nothing to place
            return scan
        self._waiting[scan.station] = scan
        if self._T_field_ref is None and scan.station == self._reference:
            self._T_field_ref = self._field_frame(scan)
        if self._T_field_ref is not None:
            for station in list(self._waiting):
                self._place(station)
        return replace(scan, green=Cloud.empty(), steady=None)

    def placed(
        self, reference: int, scans: dict[int, StationScan]
    ) -> tuple[stages.Staged[dict[int, Matrix4]], dict[int, FilteredStation]]:
        """Every station of ``scans`` levelled (with the warnings, station by station) and
        filtered, in their order; those still waiting placed now, the field frame from the
        ``reference`` (the station anchoring the plot) if it is not known yet."""
        if self._T_field_ref is None and self._waiting:
            self._T_field_ref = self._field_frame(self._waiting[reference])
        for station in list(self._waiting):
            self._place(station)
        levelled = {s: self._levelled[s].value for s in scans}
        warnings = tuple(w for s in scans for w in self._levelled[s].warnings)
        return stages.Staged(levelled, warnings), {s: self._filtered[s] for s in scans}

    def _field_frame(self, scan: StationScan) -> Matrix4:
        with self._timer.stage("levelling"):
            return T_field_reference_initial(self._calibration, scan, self._settings.ground)

    def _place(self, station: int) -> None:
        scan, ground = self._waiting.pop(station), self._settings.ground
        assert self._T_field_ref is not None
        coarse = {station: self._T_field_ref @ self._to_reference[station]}
        with self._timer.stage("levelling"):
            levelled, warnings = level_stations({station: scan}, coarse, ground)
        self._levelled[station] = stages.Staged(levelled[station], tuple(warnings))
        with self._timer.stage("filtering"):
            self._filtered[station] = stages.filter_plants(
                scan, levelled[station], self._settings.filters, ground
            )


def _per_station(
    timer: StageTimer,
    stage: str,
    items: dict[int, K],
    work: Callable[[int, K], V],
    message: Callable[[int, int], str],
) -> Generator[Progress, None, dict[int, V]]:
    """``work(station, item)`` for each station's item, timed under ``stage``, with a progress
    event ``message(index, station)`` after each; returns the results by station."""
    done: dict[int, V] = {}
    for index, (station, item) in enumerate(items.items()):
        with timer.stage(stage):
            done[station] = work(station, item)
        yield progress(stage, (index + 1) / len(items), message(index, station))
    return done


@dataclass(frozen=True)
class _Plot:
    """The stages' results that go into the :class:`Reconstruction`."""

    reference: int
    scanned: stages.ScanSummary
    fused: stages.Fused
    placed: stages.Placed
    grid: stages.GridPrior
    search: PlantSearch
    organs: dict[int, PlantOrgans]
    cautions: dict[int, tuple[str, ...]]
    crop_radius_m: float


def _with_meets(
    cautions: dict[int, tuple[str, ...]], meets: dict[int, int]
) -> dict[int, tuple[str, ...]]:
    """Each plant's cautions, with a plant whose widest extent meets another's said so."""
    notes = dict(cautions)
    for plant, other in sorted(meets.items()):
        notes[plant] = (*notes.get(plant, ()), f"{MEETS_NOTE} {other}")
    return notes


def _result(
    session_id: str,
    plot: _Plot,
    settings: ReconstructionSettings,
    timer: StageTimer,
    warnings: list[str],
) -> Reconstruction:
    """The :class:`Reconstruction` of ``plot``, its warnings logged (debug: every caller shows
    them itself, and the CLI printed each twice)."""
    for warning in warnings:  # each caller shows them (the CLI after the run, report.json)
        log.debug("reconstruction warning: %s", warning)
    placed = plot.placed
    return Reconstruction(
        session_id=session_id,
        reference=plot.reference,
        plants=plot.search.plants,
        cloud=placed.cloud,
        registrations=placed.registrations,
        T_field_reference=placed.registrations[plot.reference].T_field_station,
        kept=plot.scanned.kept | plot.fused.kept | {"doubtful_joined": plot.search.joined},
        exg_thresholds=plot.scanned.exg_thresholds,
        timings_s=dict(timer.seconds),
        cpu_s=dict(timer.cpu_seconds),
        warnings=warnings,
        separation=plot.scanned.separation,
        colour_offsets=plot.scanned.colour_offsets,
        turntable=plot.scanned.turntable,
        organs=plot.organs,
        search=plot.search,
        frame="map" if placed.T_map_field is not None else "field",
        T_map_field=placed.T_map_field,
        expected_plants=plot.grid.expected,
        flag_ambiguous_share=settings.plants.stems.flag_ambiguous_share,
        cautions=plot.cautions,
        crop_radius_m=plot.crop_radius_m,
    )
