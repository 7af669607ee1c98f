"""The paper's reference-sphere check: find each foam sphere of known diameter in the
reconstructed cloud and measure how far every point of it lies from its ideal sphere.

Per sphere, largest first: RANSAC on a voxel sample of the points above the ground (four
points, a seed and three of its neighbours, give a sphere; hypotheses whose radius is outside
the nominal +- ``radius_tolerance`` are dropped; the one with most points in a shell of
+- ``ransac_band_m`` wins), a free-radius least-squares check of the radius, then least squares
with the radius fixed to the nominal (robust soft-L1 loss, so a second, misregistered surface
does not pull the centre). The sphere's points are those within ``max_distance_m`` of the ideal
surface and ``min_height_m`` above the ground; they are then no longer available to smaller
spheres.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

log = logging.getLogger(__name__)

BIN_EDGES_CM = (0.0, 0.2, 0.5, 0.8, 1.2, np.inf)
BIN_LABELS = ("0-0.2", "0.2-0.5", "0.5-0.8", "0.8-1.2", ">1.2")


@dataclass(frozen=True)
class SphereSearch:
    """Parameters of the search (lengths in metres)."""

    radius_tolerance: float = 0.1
    ransac_band_m: float = 0.01
    max_distance_m: float = 0.03
    min_height_m: float = 0.05
    voxel_m: float = 0.01
    hypotheses: int = 3000
    min_coverage: float = 0.25
    """Least share of the upper hemisphere's area (in voxels) the inliers must cover."""
    robust_scale_m: float = 0.005
    seed: int = 0


@dataclass(frozen=True)
class SphereFit:
    """One nominal sphere: found or not, its centre (3,) in the field frame, the radius a
    free fit gives, and the distances (M,) of its points to the ideal sphere (metres)."""

    diameter_mm: float
    found: bool
    center_m: NDArray[np.float64] | None = None
    free_radius_m: float | None = None
    distances_m: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    message: str = ""


def bin_fractions(distances_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """(5,) share of the distances in each of the paper's bins (``BIN_LABELS``)."""
    if len(distances_m) == 0:
        return np.zeros(len(BIN_LABELS))
    counts, _ = np.histogram(np.abs(distances_m) * 100.0, bins=np.array(BIN_EDGES_CM))
    return counts / len(distances_m)


def within_fraction(distances_m: NDArray[np.float64], limit_cm: float) -> float:
    """Share of the distances below ``limit_cm`` (the sum of the bins up to it)."""
    if len(distances_m) == 0:
        return 0.0
    return float(np.mean(np.abs(distances_m) * 100.0 < limit_cm))


def fit_sphere(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], float] | None:
    """Algebraic least-squares sphere (centre (3,), radius) through >= 4 points (N, 3)."""
    A = np.column_stack([2.0 * points, np.ones(len(points))])
    b = (points * points).sum(axis=1)
    solution, *_ = np.linalg.lstsq(A, b, rcond=None)
    center = solution[:3]
    r2 = solution[3] + center @ center
    if not np.isfinite(r2) or r2 <= 0.0:
        return None
    return center, float(np.sqrt(r2))


def _fit_four(quads: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Spheres through (H, 4, 3) quadruples: centres (H, 3) and radii (H,), NaN if degenerate."""
    p0 = quads[:, 0, :]
    A = 2.0 * (quads[:, 1:, :] - p0[:, None, :])
    b = (quads[:, 1:, :] ** 2).sum(axis=2) - (p0**2).sum(axis=1)[:, None]
    det = np.linalg.det(A)
    ok = np.abs(det) > 1e-12
    centers = np.full((len(quads), 3), np.nan)
    centers[ok] = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
    radii = np.linalg.norm(centers - p0, axis=1)
    return centers, radii


def voxel_sample(points: NDArray[np.float64], voxel_m: float) -> NDArray[np.float64]:
    """One point (the mean) per occupied voxel of edge ``voxel_m``."""
    if len(points) == 0:
        return points
    cells = np.floor(points / voxel_m).astype(np.int64)
    _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.stack([np.bincount(inverse, points[:, i]) for i in range(3)], axis=1)
    return sums / counts[:, None]


def _ransac(
    sample: NDArray[np.float64], radius_m: float, search: SphereSearch, rng: np.random.Generator
) -> list[tuple[int, NDArray[np.float64], float]]:
    """Hypotheses (inlier count, centre, radius) within the radius bounds, best first."""
    if len(sample) < 4:
        return []
    tree = cKDTree(sample)
    seeds = sample[rng.integers(0, len(sample), search.hypotheses)]
    directions = rng.normal(size=(search.hypotheses, 3, 3))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    reach = rng.uniform(0.3, 1.0, (search.hypotheses, 3, 1)) * radius_m
    _, others = tree.query(seeds[:, None, :] + directions * reach, k=1)
    quads = np.concatenate([seeds[:, None, :], sample[others]], axis=1)
    centers, radii = _fit_four(quads)
    low, high = radius_m * (1 - search.radius_tolerance), radius_m * (1 + search.radius_tolerance)
    keep = np.flatnonzero(np.isfinite(radii) & (radii >= low) & (radii <= high))
    if len(keep) == 0:
        return []
    outer = tree.query_ball_point(
        centers[keep], radii[keep] + search.ransac_band_m, return_length=True
    )
    inner = tree.query_ball_point(
        centers[keep], radii[keep] - search.ransac_band_m, return_length=True
    )
    scores = np.asarray(outer) - np.asarray(inner)
    order = np.argsort(-scores, kind="stable")
    return [(int(scores[i]), centers[keep[i]], float(radii[keep[i]])) for i in order]


def _shell(
    points: NDArray[np.float64], center: NDArray[np.float64], radius_m: float, band_m: float
) -> NDArray[np.bool_]:
    return np.abs(np.linalg.norm(points - center, axis=1) - radius_m) <= band_m  # type: ignore[no-any-return]


def _least_squares_center(
    points: NDArray[np.float64], center: NDArray[np.float64], radius_m: float, scale_m: float
) -> NDArray[np.float64]:
    """The centre minimising the robust sum of (|p - c| - radius) over ``points`` (N, 3)."""

    def residuals(c: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.linalg.norm(points - c, axis=1) - radius_m  # type: ignore[no-any-return]

    def jacobian(c: NDArray[np.float64]) -> NDArray[np.float64]:
        offsets = points - c
        return -offsets / np.maximum(np.linalg.norm(offsets, axis=1), 1e-12)[:, None]  # type: ignore[no-any-return]

    result = least_squares(residuals, center, jac=jacobian, loss="soft_l1", f_scale=scale_m)
    return np.asarray(result.x, np.float64)


def _free_radius(points: NDArray[np.float64], center: NDArray[np.float64], scale_m: float) -> float:
    """Radius of a robust free-radius fit started at ``center``."""

    def residuals(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.linalg.norm(points - x[:3], axis=1) - x[3]  # type: ignore[no-any-return]

    start = np.append(center, np.median(np.linalg.norm(points - center, axis=1)))
    result = least_squares(residuals, start, loss="soft_l1", f_scale=scale_m)
    return float(result.x[3])


def _locate(
    sample: NDArray[np.float64], radius_m: float, search: SphereSearch, rng: np.random.Generator
) -> tuple[NDArray[np.float64], float] | str:
    """(centre, free-fit radius) of the sphere of ``radius_m`` in ``sample``, or why not."""
    hypotheses = _ransac(sample, radius_m, search, rng)
    needed = search.min_coverage * 2.0 * np.pi * radius_m**2 / search.voxel_m**2
    low, high = radius_m * (1 - search.radius_tolerance), radius_m * (1 + search.radius_tolerance)
    for score, center, radius in hypotheses[:5]:
        if score < needed:
            break
        inliers = sample[_shell(sample, center, radius, search.ransac_band_m)]
        free = _free_radius(inliers, center, search.robust_scale_m)
        if low <= free <= high:
            return center, free
    if not hypotheses:
        return "no sphere of that size in the cloud"
    best = hypotheses[0][0]
    return f"best candidate covers {best} voxels, {needed:.0f} needed, or its radius is off"


def _refine(
    points: NDArray[np.float64],
    center: NDArray[np.float64],
    radius_m: float,
    search: SphereSearch,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Least squares with the radius fixed on the full-resolution points; the final centre
    and the mask of the sphere's points (within ``max_distance_m`` of its surface)."""
    for band in (search.max_distance_m, search.max_distance_m, search.max_distance_m):
        mask = _shell(points, center, radius_m, band)
        if mask.sum() < 4:
            break
        center = _least_squares_center(points[mask], center, radius_m, search.robust_scale_m)
    return center, _shell(points, center, radius_m, search.max_distance_m)


def find_spheres(
    points_m: NDArray[np.float64], diameters_mm: list[float], search: SphereSearch | None = None
) -> list[SphereFit]:
    """Find the spheres of ``diameters_mm`` in a cloud (N, 3) in the field frame (z up, ground
    at 0); results in the order of ``diameters_mm``."""
    search = search or SphereSearch()
    rng = np.random.default_rng(search.seed)
    points = points_m[points_m[:, 2] >= search.min_height_m]
    available = np.ones(len(points), dtype=bool)
    fits: dict[int, SphereFit] = {}
    for index in sorted(range(len(diameters_mm)), key=lambda i: -diameters_mm[i]):
        diameter = diameters_mm[index]
        radius = diameter / 2000.0
        located = _locate(voxel_sample(points[available], search.voxel_m), radius, search, rng)
        if isinstance(located, str):
            log.info("sphere %g mm: not found (%s)", diameter, located)
            fits[index] = SphereFit(diameter, False, message=located)
            continue
        candidates = np.flatnonzero(available)
        center, mask = _refine(points[candidates], located[0], radius, search)
        mine = candidates[mask]
        available[mine] = False
        distances = np.linalg.norm(points[mine] - center, axis=1) - radius
        fits[index] = SphereFit(diameter, True, center, located[1], distances)
        log.info("sphere %g mm at %s: %d points", diameter, np.round(center, 4), len(mine))
    return [fits[i] for i in range(len(diameters_mm))]
