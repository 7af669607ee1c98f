"""The edges of the pose graph: which stations overlap, and each overlap registered.

Two stations overlap when their clouds, placed by the coarse poses, cover at least
``min_overlap_m2`` of the same ground (cells of ``overlap_cell_m``): on the 1.6 m plan the
side and diagonal neighbours (5.4-9 m2 on the simulated plots); stations two apart share a thin
lens at the end of both cameras' range (1.7-3.2 m2) that registers unreliably. The points of
an overlap are those in the shared cells and one cell around them (so a few cm or degrees of arrival
error do not cut the overlap short): soil, plants, spheres, anything the two stations saw.
Each overlap is registered coarse to fine by GICP (:func:`fieldapp.recon.register.icp`, one
thread per pair, so the result never depends on the thread count), and its information
matrix is the point-to-plane Hessian of the aligned overlap: flat soil constrains height and
tilt, relief, stems and spheres the position and heading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import small_gicp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, invert, transform_points
from fieldapp.recon.settings import RegistrationSettings

NORMAL_NEIGHBOURS = 12
"""Target points whose covariance gives each correspondence's normal."""


@dataclass(frozen=True)
class Overlap:
    """The points two stations share, field frame by their coarse poses: (N, 3) and (M, 3)."""

    a: int
    b: int
    points_a_m: NDArray[np.float64]
    points_b_m: NDArray[np.float64]


@dataclass(frozen=True)
class PairFit:
    """``T_a_b`` maps b's coarse field placement onto a's; ``information`` (6, 6) is in the
    frame at b's ground centre with field axes, ``[rotation, translation]``."""

    a: int
    b: int
    T_a_b: Matrix4
    information: NDArray[np.float64]
    converged: bool
    fitness: float
    rmse_m: float
    points: int


@dataclass(frozen=True)
class IcpOutcome:
    T_target_source: Matrix4
    converged: bool
    fitness: float
    rmse_m: float
    source_points: int
    target_points: int


def icp(
    target_m: NDArray[np.float64],
    source_m: NDArray[np.float64],
    settings: RegistrationSettings,
    threads: int = 1,
    init_T_target_source: Matrix4 | None = None,
) -> IcpOutcome:
    """Align ``source_m`` (N, 3) onto ``target_m`` (M, 3), coarse to fine voxel sizes
    (small_gicp); the fit is scored at the finest size. From ``init_T_target_source`` (a
    guess that agrees with the plot's other pairs within ``edge_tolerance_m`` / ``_deg``, so
    within the finest size's correspondence reach at the cameras' range) only the finest size
    runs: the coarse sizes reach far enough to slide into another minimum of smooth relief."""
    T = np.eye(4) if init_T_target_source is None else np.array(init_T_target_source)
    sizes = settings.voxel_sizes_m
    if init_T_target_source is not None:
        sizes = sizes[-1:]
    converged = True
    for voxel_m in sizes:
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


def cell_keys(points_m: NDArray[np.float64], cell_m: float) -> NDArray[np.int64]:
    """(N,) one integer per ground cell of ``cell_m`` of each point (N, 3)."""
    ij = np.floor(points_m[:, :2] / cell_m).astype(np.int64) + (1 << 20)
    keys: NDArray[np.int64] = ij[:, 0] * (1 << 21) + ij[:, 1]
    return keys


def _dilate(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    offsets = np.array([di * (1 << 21) + dj for di in (-1, 0, 1) for dj in (-1, 0, 1)])
    return np.unique((keys[:, None] + offsets[None, :]).ravel())


def thin(points_m: NDArray[np.float64], voxel_m: float) -> NDArray[np.float64]:
    """The first point (in input order) of each occupied voxel of ``voxel_m``: (K, 3)."""
    ijk = np.floor(points_m / voxel_m).astype(np.int64)
    _, first = np.unique(ijk, axis=0, return_index=True)
    return points_m[np.sort(first)]


def find_overlaps(
    points_field_m: dict[int, NDArray[np.float64]], settings: RegistrationSettings
) -> list[Overlap]:
    """Every pair of stations sharing at least ``settings.min_overlap_m2`` of ground, in
    station order; ``points_field_m``: per station (N, 3) in the field frame (coarse),
    thinned to one point per ``overlap_voxel_m`` voxel."""
    points_field_m = {s: thin(p, settings.overlap_voxel_m) for s, p in points_field_m.items()}
    keys = {s: cell_keys(p, settings.overlap_cell_m) for s, p in points_field_m.items()}
    cells = {s: np.unique(k) for s, k in keys.items()}
    stations = sorted(points_field_m)
    overlaps = []
    for i, a in enumerate(stations):
        for b in stations[i + 1 :]:
            shared = np.intersect1d(cells[a], cells[b], assume_unique=True)
            if len(shared) * settings.overlap_cell_m**2 < settings.min_overlap_m2:
                continue
            around = _dilate(shared)
            overlaps.append(
                Overlap(
                    a,
                    b,
                    points_field_m[a][np.isin(keys[a], around)],
                    points_field_m[b][np.isin(keys[b], around)],
                )
            )
    return overlaps


def register_overlap(
    overlap: Overlap,
    centre_b_m: NDArray[np.float64],
    settings: RegistrationSettings,
    init_T_a_b: Matrix4 | None = None,
) -> PairFit:
    """Align b's overlap points onto a's; ``centre_b_m`` (3,) is b's ground centre (field);
    ``init_T_a_b``: a close guess (fine voxel sizes only, see :func:`icp`), else identity."""
    outcome = icp(overlap.points_a_m, overlap.points_b_m, settings, 1, init_T_a_b)
    information = point_to_plane_information(
        overlap.points_a_m,
        transform_points(outcome.T_target_source, overlap.points_b_m),
        outcome.T_target_source,
        centre_b_m,
        settings,
        outcome.rmse_m,
    )
    return PairFit(
        overlap.a,
        overlap.b,
        outcome.T_target_source,
        information,
        outcome.converged,
        outcome.fitness,
        outcome.rmse_m,
        outcome.source_points,
    )


def point_to_plane_information(
    target_m: NDArray[np.float64],
    source_aligned_m: NDArray[np.float64],
    T_a_b: Matrix4,
    centre_b_m: NDArray[np.float64],
    settings: RegistrationSettings,
    rmse_m: float,
) -> NDArray[np.float64]:
    """(6, 6) information of the pair: the mean point-to-plane Hessian of the aligned pairs
    within ``max_correspondence_m``, times ``edge_effective_points`` / sigma^2 (sigma: the fit's
    RMSE, at least ``edge_noise_m``). Jacobians are taken for a right perturbation of node b
    (its frame at ``centre_b_m`` with field axes)."""
    tree = cKDTree(target_m)
    distances, nearest = tree.query(
        source_aligned_m, k=1, distance_upper_bound=settings.max_correspondence_m
    )
    matched = np.isfinite(distances)
    if matched.sum() < 6:
        return np.zeros((6, 6))
    _, around = tree.query(target_m[nearest[matched]], k=min(NORMAL_NEIGHBOURS, len(target_m)))
    neighbourhoods = target_m[around]  # (K, n, 3)
    centred = neighbourhoods - neighbourhoods.mean(axis=1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("kni,knj->kij", centred, centred))
    normals: NDArray[np.float64] = vectors[:, :, 0] @ T_a_b[:3, :3]  # b's axes (R^T n, rows)
    q = transform_points(invert(T_a_b), source_aligned_m[matched]) - centre_b_m
    J = np.concatenate([np.cross(q, normals), normals], axis=1)  # (K, 6)
    sigma = max(rmse_m if np.isfinite(rmse_m) else 0.0, settings.edge_noise_m)
    return (J.T @ J) / len(J) * settings.edge_effective_points / sigma**2  # type: ignore[no-any-return]
