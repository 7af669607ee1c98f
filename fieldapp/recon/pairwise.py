"""The edges of the pose graph: which stations overlap, and each overlap registered.

Two stations overlap when their clouds, placed by the coarse poses, cover at least
``min_overlap_m2`` of the same ground (cells of ``overlap_cell_m``): on the 1.6 m plan the
side and diagonal neighbours (5.4-9 m2 on the simulated plots); stations two apart share a thin
lens at the end of both cameras' range (1.7-3.2 m2) that registers unreliably. The points of
an overlap are all the two stations saw there (soil, plants, spheres, anything): b's (the
source) in the shared cells, a's (the target) in the shared cells and one cell around them, so
a few cm or degrees of arrival error neither cut the overlap short nor leave source points
with nothing to match (b's points beyond a's view pulled the fit towards a's edge).
Each overlap is registered coarse to fine by GICP (:func:`align`), and its information
matrix is the point-to-plane Hessian of the aligned overlap: flat soil constrains height and
tilt, relief, stems and spheres the position and heading.

The result never depends on the thread count: only the k-d trees, the point covariances and
normals (each point's its own) and the edge's nearest-neighbour queries (each its own) run on
the ``threads`` OpenMP threads; voxel sampling (small_gicp's
multi-threaded sampling varies from run to run) and the optimisation (its reduction sums in
the threads' order) run on one. The OpenMP threads sleep between parallel regions
(``OMP_WAIT_POLICY=PASSIVE``, unless set otherwise before small_gicp loads): spinning, two
threads cost 75 % more CPU than one. small_gicp holds Python's GIL, so pairs registered on
several Python threads overlap only in their numpy and scipy parts.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, transform_points
from fieldapp.recon.settings import RegistrationSettings

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # read once, when small_gicp's libgomp loads
import small_gicp

COVARIANCE_NEIGHBOURS = 10
"""Points whose covariance GICP gives each point (small_gicp's default)."""


@dataclass(frozen=True)
class Overlap:
    """The points two stations share, field frame by their coarse poses: a's (N, 3) in the
    shared cells and one cell around them, b's (M, 3) in the shared cells."""

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


def preprocess(
    points_m: NDArray[np.float64], voxel_m: float, threads: int = 1
) -> tuple[small_gicp.PointCloud, small_gicp.KdTree]:
    """``points_m`` (N, 3) as GICP takes them: one point (the mean) per voxel of ``voxel_m``,
    each with the covariance and the normal of its ``COVARIANCE_NEIGHBOURS`` nearest (the
    normal at no extra cost: the edge's information uses it), and their k-d tree; the same for
    any ``threads`` (see the module's docstring)."""
    cloud = small_gicp.voxelgrid_sampling(points_m, voxel_m, num_threads=1)
    tree = small_gicp.KdTree(cloud, num_threads=threads)
    small_gicp.estimate_normals_covariances(cloud, tree, COVARIANCE_NEIGHBOURS, num_threads=threads)
    return cloud, tree


@dataclass(frozen=True)
class Aligned:
    """A ladder's result: ``T_target_source``, whether its last size converged, and the
    finest size's prepared clouds (``target`` with its ``tree``, ``source``)."""

    T_target_source: Matrix4
    converged: bool
    target: Any
    tree: Any
    source: Any


def cloud_sizes_m(settings: RegistrationSettings) -> list[float]:
    """The voxel size each of ``voxel_sizes_m`` is run on: its own, but the sizes at or
    below ``shared_cloud_m`` all run on the finest size's cloud, each with its own reach."""
    finest = settings.voxel_sizes_m[-1]
    return [finest if v <= settings.shared_cloud_m else v for v in settings.voxel_sizes_m]


def align(
    target_m: NDArray[np.float64],
    source_m: NDArray[np.float64],
    settings: RegistrationSettings,
    threads: int = 1,
    init_T_target_source: Matrix4 | None = None,
) -> tuple[Matrix4, bool]:
    """``T_target_source`` aligning ``source_m`` (N, 3) onto ``target_m`` (M, 3) coarse to
    fine over the voxel sizes (small_gicp), and whether the last size converged
    (:func:`ladder`)."""
    aligned = ladder(target_m, source_m, settings, threads, init_T_target_source)
    return aligned.T_target_source, aligned.converged


def ladder(
    target_m: NDArray[np.float64],
    source_m: NDArray[np.float64],
    settings: RegistrationSettings,
    threads: int = 1,
    init_T_target_source: Matrix4 | None = None,
) -> Aligned:
    """GICP coarse to fine over ``voxel_sizes_m``, each size reaching
    ``correspondence_factor`` times itself, on the clouds of :func:`cloud_sizes_m` (each
    prepared once). From ``init_T_target_source`` (a guess that agrees with the plot's other
    pairs within ``edge_tolerance_m`` / ``_deg``, so within the finest size's correspondence
    reach at the cameras' range) only the finest size runs: the coarse sizes reach far enough
    to slide into another minimum of smooth relief."""
    T = np.eye(4) if init_T_target_source is None else np.array(init_T_target_source)
    levels = list(zip(settings.voxel_sizes_m, cloud_sizes_m(settings), strict=True))
    if init_T_target_source is not None:
        levels = levels[-1:]
    converged, prepared_m = True, -1.0
    for voxel_m, cloud_m in levels:
        if cloud_m != prepared_m:
            (target, tree), (source, _) = (
                preprocess(target_m, cloud_m, threads),
                preprocess(source_m, cloud_m, threads),
            )
            prepared_m = cloud_m
        T, converged = gicp(target, source, tree, T, settings, voxel_m)
    return Aligned(T, converged, target, tree, source)


def gicp(
    target: Any, source: Any, tree: Any, T: Matrix4, settings: RegistrationSettings, voxel_m: float
) -> tuple[Matrix4, bool]:
    """One GICP run of prepared ``source`` onto ``target`` (and its ``tree``) from ``T`` with
    the reach of voxel size ``voxel_m``, on one thread (see the module's docstring):
    ``T_target_source`` and whether it converged."""
    result = small_gicp.align(
        target,
        source,
        tree,
        init_T_target_source=T,
        registration_type=settings.method,
        max_correspondence_distance=max(
            settings.max_correspondence_m, settings.correspondence_factor * voxel_m
        ),
        num_threads=1,
        max_iterations=settings.max_iterations,
    )
    return np.asarray(result.T_target_source, dtype=np.float64), bool(result.converged)


def thinned(points_m: NDArray[np.float64], voxel_m: float) -> tuple[Any, Any]:
    """small_gicp's own preparation of ``points_m`` (N, 3) at ``voxel_m``, on one thread: the
    cloud and its tree."""
    cloud, tree = small_gicp.preprocess_points(points_m, voxel_m, num_threads=1)
    return cloud, tree


def icp(
    target_m: NDArray[np.float64],
    source_m: NDArray[np.float64],
    settings: RegistrationSettings,
    threads: int = 1,
    init_T_target_source: Matrix4 | None = None,
) -> IcpOutcome:
    """:func:`align`, the fit scored on all the points (:func:`score`)."""
    T, converged = align(target_m, source_m, settings, threads, init_T_target_source)
    fitness, rmse = score(target_m, transform_points(T, source_m), settings.max_correspondence_m)
    return IcpOutcome(T, converged, fitness, rmse, len(source_m), len(target_m))


@dataclass(frozen=True)
class Matches:
    """Each source point's nearest target point: ``distances_m`` (N,) (``inf`` beyond the
    reach), ``nearest`` (N,) indices into the target points, ``tree`` the target's k-d tree."""

    tree: cKDTree
    distances_m: NDArray[np.float64]
    nearest: NDArray[np.intp]

    @property
    def matched(self) -> NDArray[np.bool_]:
        """(N,) the source points with a target point within reach."""
        return np.isfinite(self.distances_m)


def match(
    target_m: NDArray[np.float64], source_m: NDArray[np.float64], max_distance_m: float
) -> Matches:
    """Nearest target point (M, 3) of each source point (N, 3) within ``max_distance_m``."""
    tree = cKDTree(target_m)
    distances, nearest = tree.query(source_m, k=1, distance_upper_bound=max_distance_m)
    return Matches(tree, distances, nearest)


def fitness_rmse(matches: Matches) -> tuple[float, float]:
    """(fitness, RMSE in metres): the share of source points matched and the RMS distance of
    the matched pairs (Open3D's definitions)."""
    matched = matches.matched
    if not matched.any():
        return 0.0, float("nan")
    return float(matched.mean()), float(np.sqrt(np.mean(matches.distances_m[matched] ** 2)))


def score(
    target_m: NDArray[np.float64], source_m: NDArray[np.float64], max_distance_m: float
) -> tuple[float, float]:
    """(fitness, RMSE in metres) of ``source_m`` (N, 3) on ``target_m`` (M, 3): pairs within
    ``max_distance_m`` (:func:`fitness_rmse`)."""
    if len(source_m) == 0 or len(target_m) == 0:
        return 0.0, float("nan")
    return fitness_rmse(match(target_m, source_m, max_distance_m))


def cell_keys(points_m: NDArray[np.float64], cell_m: float) -> NDArray[np.int64]:
    """(N,) one integer per ground cell of ``cell_m`` of each point (N, 3)."""
    ij = np.floor(points_m[:, :2] / cell_m).astype(np.int64) + (1 << 20)
    keys: NDArray[np.int64] = ij[:, 0] * (1 << 21) + ij[:, 1]
    return keys


def _in_cells(
    cells: NDArray[np.int64], cell_of: NDArray[np.intp], wanted: NDArray[np.int64]
) -> NDArray[np.bool_]:
    """(N,) which points lie in one of the ``wanted`` cells, each point's cell given by its
    index ``cell_of`` (N,) into the station's sorted unique ``cells``."""
    return np.isin(cells, wanted, assume_unique=True)[cell_of]


def _dilate(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    offsets = np.array([di * (1 << 21) + dj for di in (-1, 0, 1) for dj in (-1, 0, 1)])
    return np.unique((keys[:, None] + offsets[None, :]).ravel())


def thin(points_m: NDArray[np.float64], voxel_m: float) -> NDArray[np.float64]:
    """The first point (in input order) of each occupied voxel of ``voxel_m``: (K, 3)."""
    ijk = np.floor(points_m / voxel_m).astype(np.int64) + (1 << 20)  # 21 bits per axis
    keys = (ijk[:, 0] << 42) + (ijk[:, 1] << 21) + ijk[:, 2]  # one sort of (N,), not of rows
    _, first = np.unique(keys, return_index=True)
    return points_m[np.sort(first)]


def overlapping(
    a: int,
    b: int,
    area_m2: dict[tuple[int, int], float],
    largest_m2: dict[int, float],
    settings: RegistrationSettings,
) -> bool:
    """Whether stations ``a`` and ``b`` (a < b) overlap enough to register, by the ground area
    the pair shares (``area_m2``) and each station's largest shared area (``largest_m2``,
    :func:`largest_overlaps`): ``min_overlap_m2``, or ``min_overlap_share`` of the larger of the
    two stations' largest and at least ``min_overlap_floor_m2``.

    The absolute bar was set on the simulated rig (1.3 m, 45 degrees: side and diagonal
    neighbours share 5.4-9 m2, stations two apart 1.7-3.2 m2). An independent renderer's rig
    (1.55 m, 37.5 degrees: the camera sees ground from 0.64 m out) left its neighbours 2.9-3.9
    m2 and no pair at all: every station kept its coarse pose. Relative to the stations' own
    largest overlaps its neighbours share 0.75-1.0 and stations two apart at most 0.5 of it;
    on every simulated plot measured, the pairs under the bar at most 0.41."""
    area = area_m2[(a, b)]
    if area >= settings.min_overlap_m2:
        return True
    bar = settings.min_overlap_share * max(largest_m2[a], largest_m2[b])
    return area >= max(bar, settings.min_overlap_floor_m2)


def largest_overlaps(area_m2: dict[tuple[int, int], float]) -> dict[int, float]:
    """Each station's largest shared area over the pairs of ``area_m2``."""
    largest: dict[int, float] = {}
    for (a, b), area in area_m2.items():
        largest[a] = max(largest.get(a, 0.0), area)
        largest[b] = max(largest.get(b, 0.0), area)
    return largest


def find_overlaps(
    points_field_m: dict[int, NDArray[np.float64]], settings: RegistrationSettings
) -> list[Overlap]:
    """Every pair of stations sharing ground (:func:`overlapping`), in station order;
    ``points_field_m``: per station (N, 3) in the field frame (coarse), thinned to one point
    per ``overlap_voxel_m`` voxel."""
    points_field_m = {s: thin(p, settings.overlap_voxel_m) for s, p in points_field_m.items()}
    # each station's cells once, and which cell each point is in: a pair's points are then its
    # cells' membership gathered per point (the same masks as np.isin over every point, for a
    # fifth of the cost: a station has 60 000 points in 2 000 cells)
    cells, cell_of = {}, {}
    for s, p in points_field_m.items():
        cells[s], cell_of[s] = np.unique(cell_keys(p, settings.overlap_cell_m), return_inverse=True)
    stations = sorted(points_field_m)
    shared_cells = {
        (a, b): np.intersect1d(cells[a], cells[b], assume_unique=True)
        for i, a in enumerate(stations)
        for b in stations[i + 1 :]
    }
    area_m2 = {pair: len(c) * settings.overlap_cell_m**2 for pair, c in shared_cells.items()}
    largest_m2 = largest_overlaps(area_m2)
    overlaps = []
    for (a, b), shared in shared_cells.items():
        if overlapping(a, b, area_m2, largest_m2, settings):
            overlaps.append(
                Overlap(
                    a,
                    b,
                    points_field_m[a][_in_cells(cells[a], cell_of[a], _dilate(shared))],
                    points_field_m[b][_in_cells(cells[b], cell_of[b], shared)],
                )
            )
    return overlaps


def register_overlap(
    overlap: Overlap,
    centre_b_m: NDArray[np.float64],
    settings: RegistrationSettings,
    init_T_a_b: Matrix4 | None = None,
    threads: int = 1,
) -> PairFit:
    """Align b's overlap points onto a's; ``centre_b_m`` (3,) is b's ground centre (field);
    ``init_T_a_b``: a close guess (fine voxel sizes only, see :func:`ladder`), else identity.
    The fit is scored and its information taken from one matching of the finest size's
    clouds, already prepared by GICP (:func:`edge`)."""
    target_m, source_m = overlap.points_a_m, overlap.points_b_m
    if len(target_m) == 0 or len(source_m) == 0:
        return PairFit(overlap.a, overlap.b, np.eye(4), np.zeros((6, 6)), False, 0.0, np.nan, 0)
    aligned = ladder(target_m, source_m, settings, threads, init_T_a_b)
    fitness, rmse, information = edge(aligned, centre_b_m, settings, threads)
    return PairFit(
        overlap.a,
        overlap.b,
        aligned.T_target_source,
        information,
        aligned.converged,
        fitness,
        rmse,
        len(source_m),
    )


def edge(
    aligned: Aligned, centre_b_m: NDArray[np.float64], settings: RegistrationSettings, threads: int
) -> tuple[float, float, NDArray[np.float64]]:
    """(fitness, RMSE in metres, (6, 6) information) of a fit: each point of the finest
    source cloud, aligned, matched to its nearest target point (small_gicp's tree, each query
    its own: the same on any thread count) within ``max_correspondence_m``; the share matched
    and their RMS distance (Open3D's definitions), and :func:`point_to_plane_information` with
    the normals GICP's preparation estimated."""
    source_m = np.asarray(aligned.source.points()[:, :3])
    nearest, squared = aligned.tree.batch_nearest_neighbor_search(
        transform_points(aligned.T_target_source, source_m), num_threads=threads
    )
    nearest, squared = np.asarray(nearest), np.asarray(squared)
    matched = squared <= settings.max_correspondence_m**2
    if not matched.any():
        return 0.0, float("nan"), np.zeros((6, 6))
    rmse = float(np.sqrt(np.mean(squared[matched])))
    normals_m = np.asarray(aligned.target.normals()[nearest[matched], :3])
    information = point_to_plane_information(
        source_m[matched] - centre_b_m,
        normals_m @ aligned.T_target_source[:3, :3],
        settings,
        rmse,
    )
    return float(matched.mean()), rmse, information


def point_to_plane_information(
    q_m: NDArray[np.float64],
    normals: NDArray[np.float64],
    settings: RegistrationSettings,
    rmse_m: float,
) -> NDArray[np.float64]:
    """(6, 6) information of the pair: the mean point-to-plane Hessian of its matched points
    ``q_m`` (K, 3), relative to node b (its frame at b's ground centre with field axes), each
    with its target's unit normal (K, 3) in b's axes, times ``edge_effective_points`` /
    sigma^2 (sigma: the fit's RMSE, at least ``edge_noise_m``). Jacobians are taken for a
    right perturbation of node b."""
    if len(q_m) < 6:
        return np.zeros((6, 6))
    J = np.concatenate([np.cross(q_m, normals), normals], axis=1)  # (K, 6)
    sigma = max(rmse_m if np.isfinite(rmse_m) else 0.0, settings.edge_noise_m)
    return (J.T @ J) / len(J) * settings.edge_effective_points / sigma**2  # type: ignore[no-any-return]
