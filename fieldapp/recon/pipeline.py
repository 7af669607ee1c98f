"""The reconstruction, step by step as the paper describes it.

``reconstruct(session, settings)`` is a generator: it yields :class:`Progress` events between
steps (closing it cancels the work there) and returns a :class:`Reconstruction`.
:func:`run_reconstruction` is the blocking form.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Generator, Iterator
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert, transform_points
from fieldapp.errors import FieldappError
from fieldapp.io.session import Session
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.filters import FilteredStation, filter_station, remove_outliers, voxel_mean
from fieldapp.recon.guards import COARSE_KEPT, UNRELIABLE
from fieldapp.recon.levelling import T_field_reference_initial, level_stations
from fieldapp.recon.mapframe import (
    in_map_frame,
    map_alignment,
    session_grid,
    station_map_poses,
    turntable_axis_direction,
)
from fieldapp.recon.organ_traits import foot_m, measure_organs
from fieldapp.recon.plants import search_plants
from fieldapp.recon.progress import Progress, StageTimer, progress
from fieldapp.recon.register import StationRegistration, register_stations
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.scans import StationScan, read_stations, turntable_axis_point
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.recon.turntable import carries_plant, read_turntable

log = logging.getLogger(__name__)

T = TypeVar("T")


class NothingUsable(FieldappError):
    """The session holds nothing that can be reconstructed."""


def reconstruct(
    session: Session, settings: ReconstructionSettings
) -> Generator[Progress, None, Reconstruction]:
    """Reconstruct ``session``: local reconstruction of each station, levelling, plant
    filtering, global registration, plants and their traits, organs and theirs."""
    timer, warnings = StageTimer(), _missing_warnings(session)
    calibration = session.calibration
    if calibration.view_step is None or calibration.stations is None:
        raise NothingUsable(f"{session.folder}: the calibration cannot join views and stations")
    to_reference = calibration.stations.to_reference

    # 1-2. Depth to points, every view of a station into its view 0 (Eq. 9).
    scans: dict[int, StationScan] = {}
    table = None
    if carries_plant(session):  # camera fixed, plant turning: the room masked
        with timer.stage("local reconstruction"):
            table = read_turntable(session, settings, warnings)
        if table is not None:
            scans[table.scan.station] = table.scan
        yield progress("local reconstruction", 1.0, "turntable views joined")
    else:
        for index, count, scan in _timed_iter(
            timer, "local reconstruction", read_stations(session, settings, warnings)
        ):
            if scan is not None and scan.station not in to_reference:
                warnings.append(f"station {scan.station} has no to_reference calibration: skipped")
            elif scan is not None:
                scans[scan.station] = scan
            yield progress(
                "local reconstruction", (index + 1) / count, f"station {index + 1} of {count}"
            )
    if not scans:
        raise NothingUsable(f"{session.folder}: no capture could be read")
    reference = _reference_station(calibration.stations.reference, scans, to_reference, warnings)

    # 3. Levelling: coarse placement by the pre-calibration, each station on its own ground.
    with timer.stage("levelling"):
        if table is not None:
            T_field_coarse = {reference: table.T_field_view0}
        else:
            T_field_ref = T_field_reference_initial(calibration, scans[reference], settings.ground)
            T_field_coarse = {s: T_field_ref @ to_reference[s] for s in scans}
        T_field_levelled = level_stations(scans, T_field_coarse, settings.ground, warnings)
    yield progress("levelling", 1.0, "stations levelled")

    # 4. Plant filtering per station: pass-through above the ground, voxel means.
    filtered: dict[int, FilteredStation] = {}
    for i, (station, scan) in enumerate(scans.items()):
        with timer.stage("filtering"):
            filtered[station] = filter_station(
                scan.green.transformed(T_field_levelled[station]),
                scan.soil.transformed(T_field_levelled[station]),
                settings.filters,
                settings.ground.soil_band_m,
                settings.ground.soil_voxel_m,
                scan.separation.by_geometry,
            )
        yield progress("filtering", (i + 1) / len(scans), f"station {station} filtered")
    separation = {s: scan.separation.describe() for s, scan in scans.items()}
    exg_thresholds = {
        s: scan.exg_threshold for s, scan in scans.items() if not scan.separation.by_geometry
    }
    measured_pixels = sum(scan.measured_pixels for scan in scans.values())
    scans.clear()  # the station clouds are no longer needed

    # 5. Global registration: one pose graph of every overlap, the coarse poses as its prior.
    steps = register_stations(
        _registration_points(filtered, T_field_levelled, settings),
        T_field_levelled,
        turntable_axis_point(calibration.view_step.matrix, calibration.view_step.views_per_turn),
        reference,
        settings.registration,
        settings.threads,
    )
    registrations = yield from _timed_steps(timer, "registration", steps)
    yield progress("registration", 1.0, f"{len(registrations)} stations placed")
    for station, registration in registrations.items():
        if registration.verdict in (COARSE_KEPT, UNRELIABLE) and settings.registration.enabled:
            warnings.append(f"station {station} {registration.verdict}: {registration.message}")

    # 6. One cloud of the plot; outliers removed where every station's view is together.
    with timer.stage("outlier removal"):
        cloud, soil = _fuse(filtered, registrations, settings.filters.voxel_size_m)
        kept = {"fused": len(cloud)}
        cloud, outlier_counts = remove_outliers(cloud, settings.filters, settings.threads)
    yield progress("plants", 0.5, "outliers removed")

    # 7-8. Plants from their stems and their traits, in plot coordinates (the map's x and y).
    with timer.stage("plants"):
        T_map_field = map_alignment(
            station_map_poses(session),
            {s: r.T_field_station for s, r in registrations.items()},
            turntable_axis_point(
                calibration.view_step.matrix, calibration.view_step.views_per_turn
            ),
            turntable_axis_direction(calibration.view_step.matrix),
        )
        if T_map_field is not None:
            cloud, soil, registrations = in_map_frame(T_map_field, cloud, soil, registrations)
        grid, expected = session_grid(session, T_map_field, warnings)
        search = search_plants(
            cloud, soil, settings.plants, settings.ground.local_ground_radius_m, grid
        )
        plants = search.plants
        warnings.extend(search.warnings(settings.plants.stems.flag_ambiguous_share))
    with timer.stage("organs"):
        organs = {p.id: measure_organs(p.cloud.points, foot_m(p.traits)) for p in plants}
    yield progress("traits", 1.0, f"{len(plants)} plants")
    if not plants:
        warnings.append("no plant found")
    for warning in warnings:
        log.warning("%s", warning)
    return Reconstruction(
        session_id=session.id,
        reference=reference,
        plants=plants,
        cloud=cloud,
        registrations=registrations,
        T_field_reference=registrations[reference].T_field_station,
        kept={"measured_pixels": measured_pixels} | _sum_kept(filtered) | kept | outlier_counts,
        exg_thresholds=exg_thresholds,
        timings_s=dict(timer.seconds),
        cpu_s=dict(timer.cpu_seconds),
        warnings=warnings,
        separation=separation,
        turntable=table.report if table is not None else None,
        organs=organs,
        search=search,
        frame="map" if T_map_field is not None else "field",
        T_map_field=T_map_field,
        expected_plants=expected,
        flag_ambiguous_share=settings.plants.stems.flag_ambiguous_share,
    )


def run_reconstruction(
    session: Session,
    settings: ReconstructionSettings,
    on_progress: Callable[[Progress], None] | None = None,
) -> Reconstruction:
    """Run :func:`reconstruct` to the end, passing each progress event to ``on_progress``."""
    steps = reconstruct(session, settings)
    while True:
        try:
            event = next(steps)
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]
        if on_progress is not None:
            on_progress(event)


def _timed_iter(timer: StageTimer, stage: str, steps: Iterator[T]) -> Iterator[T]:
    """``steps`` with the time spent producing each item (not the caller's) added to ``stage``."""
    while True:
        with timer.stage(stage):
            item = next(steps, _END)
        if item is _END:
            return
        yield item  # type: ignore[misc]


_END = object()


R = TypeVar("R")


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


def _missing_warnings(session: Session) -> list[str]:
    missing = session.missing()
    if not missing:
        return []
    listed = ", ".join(f"s{s} v{v}" for s, v in missing)
    return [f"{len(missing)} captures missing: {listed}"]


def _reference_station(
    reference: int,
    scans: dict[int, StationScan],
    to_reference: dict[int, Matrix4],
    warnings: list[str],
) -> int:
    """The calibrated reference station, or the read station nearest to it when it is missing."""
    if reference in scans:
        return reference
    nearest = min(scans, key=lambda s: (float(np.linalg.norm(to_reference[s][:3, 3])), s))
    warnings.append(
        f"reference station {reference} has no usable capture: station {nearest} anchors the plot"
    )
    return nearest


def _registration_points(
    filtered: dict[int, FilteredStation],
    T_field_levelled: dict[int, Matrix4],
    settings: ReconstructionSettings,
) -> dict[int, NDArray[np.float64]]:
    """Per station, the points ICP aligns (plants, and soil when set), in its view-0 frame."""
    points = {}
    for station, result in filtered.items():
        chosen = [result.plants.points]
        if settings.registration.include_soil:
            chosen.append(result.soil_m)
        points[station] = transform_points(
            invert(T_field_levelled[station]), np.concatenate(chosen)
        )
    return points


def _fuse(
    filtered: dict[int, FilteredStation],
    registrations: dict[int, StationRegistration],
    voxel_m: float,
) -> tuple[Cloud, NDArray[np.float64]]:
    """The plant cloud and the soil sample of the plot in the field frame, overlaps averaged."""
    plants = Cloud.concatenate(
        [f.plants.transformed(registrations[s].T_correction) for s, f in filtered.items()]
    )
    soil = [transform_points(registrations[s].T_correction, f.soil_m) for s, f in filtered.items()]
    return voxel_mean(plants, voxel_m), np.concatenate(soil)


def _sum_kept(filtered: dict[int, FilteredStation]) -> dict[str, int]:
    total: dict[str, int] = {}
    for result in filtered.values():
        for name, count in result.kept.items():
            total[name] = total.get(name, 0) + count
    return total
