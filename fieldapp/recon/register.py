"""Global registration: coarse by the station pre-calibration, fine by ICP on station overlaps.

Stations are refined outward from the reference station (Prim's order on the distance between
station centres), each against what is already placed. The ICP runs on the points inside the
overlap sphere of the station and each placed neighbour: centred between the two station
centres (on the ground), the centres' distance as diameter. A refinement that does not converge,
fits badly or moves the station implausibly far is rejected: the coarse transform is kept.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import small_gicp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, rotation_angle_deg, transform_points
from fieldapp.recon.settings import RegistrationSettings

log = logging.getLogger(__name__)

NEIGHBOUR_FACTOR = 1.25
"""Placed stations within this factor of the nearest one's distance are also neighbours."""


@dataclass(frozen=True)
class StationRegistration:
    """How one station was placed. ``T_correction`` maps its coarse field placement onto the
    fine one (identity when ICP was off or rejected)."""

    station: int
    T_field_station: Matrix4
    T_correction: Matrix4
    neighbours: list[int] = field(default_factory=list)
    fitness: float | None = None
    rmse_m: float | None = None
    accepted: bool = False
    message: str = ""


@dataclass(frozen=True)
class IcpOutcome:
    T_target_source: Matrix4
    converged: bool
    fitness: float
    rmse_m: float
    source_points: int
    target_points: int


def registration_order(
    centres_m: dict[int, NDArray[np.float64]], reference: int
) -> list[tuple[int, list[int]]]:
    """(station, placed neighbours) from the reference outward: stations by their distance to
    the reference; the neighbours of each are the placed stations within
    :data:`NEIGHBOUR_FACTOR` of the nearest placed one."""

    def distance(a: int, b: int) -> float:
        return float(np.linalg.norm(centres_m[a] - centres_m[b]))

    placed = [reference]
    order: list[tuple[int, list[int]]] = []
    for station in sorted(
        (s for s in centres_m if s != reference), key=lambda s: (distance(s, reference), s)
    ):
        nearest = min(distance(station, p) for p in placed)
        neighbours = sorted(p for p in placed if distance(station, p) <= NEIGHBOUR_FACTOR * nearest)
        order.append((station, neighbours))
        placed.append(station)
    return order


def overlap_mask(
    points_m: NDArray[np.float64], centre_a_m: NDArray[np.float64], centre_b_m: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Mask of ``points_m`` (N, 3) inside the sphere between two station centres (3,)."""
    middle = (centre_a_m + centre_b_m) / 2.0
    radius = float(np.linalg.norm(centre_a_m - centre_b_m)) / 2.0
    return np.sum((points_m - middle) ** 2, axis=1) <= radius**2  # type: ignore[no-any-return]


def icp(
    target_m: NDArray[np.float64],
    source_m: NDArray[np.float64],
    settings: RegistrationSettings,
    threads: int = 1,
) -> IcpOutcome:
    """Align ``source_m`` (N, 3) onto ``target_m`` (M, 3), coarse to fine voxel sizes
    (small_gicp); the fit is scored at the finest size."""
    T = np.eye(4)
    converged = True
    target = source = None
    tree = None
    for voxel_m in settings.voxel_sizes_m:
        target, tree = small_gicp.preprocess_points(target_m, voxel_m, num_threads=threads)
        source, _ = small_gicp.preprocess_points(source_m, voxel_m, num_threads=threads)
        result = small_gicp.align(
            target,
            source,
            tree,
            init_T_target_source=T,
            registration_type=settings.method,
            max_correspondence_distance=max(
                settings.max_correspondence_m, settings.correspondence_factor * voxel_m
            ),
            num_threads=threads,
            max_iterations=settings.max_iterations,
        )
        T = np.asarray(result.T_target_source, dtype=np.float64)
        converged = bool(result.converged)
    fitness, rmse = score(target_m, transform_points(T, source_m), settings.max_correspondence_m)
    return IcpOutcome(T, converged, fitness, rmse, len(source_m), len(target_m))


def score(
    target_m: NDArray[np.float64], source_m: NDArray[np.float64], max_distance_m: float
) -> tuple[float, float]:
    """(fitness, RMSE in metres): the share of source points with a target point within
    ``max_distance_m`` and the RMS distance of those pairs (Open3D's definitions)."""
    if len(source_m) == 0 or len(target_m) == 0:
        return 0.0, float("nan")
    distances, _ = cKDTree(target_m).query(source_m, k=1, distance_upper_bound=max_distance_m)
    inliers = np.isfinite(distances)
    if not inliers.any():
        return 0.0, float("nan")
    return float(inliers.mean()), float(np.sqrt(np.mean(distances[inliers] ** 2)))


def plausibility_problem(
    outcome: IcpOutcome, centre_m: NDArray[np.float64], settings: RegistrationSettings
) -> str | None:
    """Why an ICP result must be rejected, or ``None`` when it is acceptable."""
    if not outcome.converged:
        return "ICP did not converge"
    shift = float(
        np.linalg.norm(transform_points(outcome.T_target_source, centre_m[None])[0] - centre_m)
    )
    if shift > settings.max_translation_m:
        limit_mm = settings.max_translation_m * 1000
        return f"ICP moved the station {shift * 1000:.0f} mm (limit {limit_mm:.0f} mm)"
    angle = rotation_angle_deg(outcome.T_target_source[:3, :3])
    if angle > settings.max_rotation_deg:
        return f"ICP turned the station {angle:.1f} deg (limit {settings.max_rotation_deg:g} deg)"
    if outcome.fitness < settings.min_fitness:
        return f"ICP fitness {outcome.fitness:.2f} below {settings.min_fitness:g}"
    return None


def ground_centre_m(
    T_field_station: Matrix4, axis_point_station_m: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Where the station's turntable axis meets the ground (z = 0), field frame (3,)."""
    centre: NDArray[np.float64] = transform_points(T_field_station, axis_point_station_m[None])[0]
    centre[2] = 0.0
    return centre


def register_stations(
    points_station_m: dict[int, NDArray[np.float64]],
    T_field_station_coarse: dict[int, Matrix4],
    axis_point_station_m: NDArray[np.float64],
    reference: int,
    settings: RegistrationSettings,
    threads: int = 1,
) -> Iterator[StationRegistration]:
    """Place every station, the reference first, then outward; yields each as it is placed.

    ``points_station_m``: per station, the (N, 3) points ICP works on, in its view-0 frame.
    ``axis_point_station_m``: (3,) a point of the turntable axis in view-0 frame.
    """
    placed: dict[int, StationRegistration] = {}
    centres = {
        s: ground_centre_m(T, axis_point_station_m) for s, T in T_field_station_coarse.items()
    }
    first = StationRegistration(
        reference, T_field_station_coarse[reference], np.eye(4), accepted=True, message="reference"
    )
    placed[reference] = first
    yield first
    for station, neighbours in registration_order(centres, reference):
        done = _place(
            station,
            neighbours,
            points_station_m,
            T_field_station_coarse,
            placed,
            axis_point_station_m,
            settings,
            threads,
        )
        placed[station] = done
        yield done


def _place(
    station: int,
    neighbours: list[int],
    points_station_m: dict[int, NDArray[np.float64]],
    T_field_station_coarse: dict[int, Matrix4],
    placed: dict[int, StationRegistration],
    axis_point_station_m: NDArray[np.float64],
    settings: RegistrationSettings,
    threads: int,
) -> StationRegistration:
    T_coarse = T_field_station_coarse[station]

    def kept(message: str, outcome: IcpOutcome | None = None) -> StationRegistration:
        return StationRegistration(
            station,
            T_coarse,
            np.eye(4),
            neighbours,
            outcome.fitness if outcome else None,
            outcome.rmse_m if outcome else None,
            accepted=False,
            message=message,
        )

    if not settings.enabled:
        return kept("ICP off: coarse transform")
    centre = ground_centre_m(T_coarse, axis_point_station_m)
    source = transform_points(T_coarse, points_station_m[station])
    source_mask = np.zeros(len(source), dtype=bool)
    targets = []
    for neighbour in neighbours:
        done = placed[neighbour]
        neighbour_centre = ground_centre_m(done.T_field_station, axis_point_station_m)
        target = transform_points(done.T_field_station, points_station_m[neighbour])
        targets.append(target[overlap_mask(target, centre, neighbour_centre)])
        source_mask |= overlap_mask(source, centre, neighbour_centre)
    target = np.concatenate(targets) if targets else np.zeros((0, 3))
    source = source[source_mask]
    if min(len(source), len(target)) < settings.min_points:
        return kept(
            f"too few points in the overlap ({len(source)} / {len(target)}): coarse transform kept"
        )
    outcome = icp(target, source, settings, threads)
    problem = plausibility_problem(outcome, centre, settings)
    if problem:
        return kept(f"{problem}: coarse transform kept", outcome)
    return StationRegistration(
        station,
        outcome.T_target_source @ T_coarse,
        outcome.T_target_source,
        neighbours,
        outcome.fitness,
        outcome.rmse_m,
        accepted=True,
        message="ICP refined",
    )
