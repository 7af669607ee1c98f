"""Checkerboard corners lifted to 3D with the registered depth: a robust local plane fit around
each corner, intersected with the corner's viewing ray (never one noisy depth pixel)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import Intrinsics

MIN_PLANE_PIXELS = 12
CORNER_SIGMA_PX = 0.25
"""Typical sub-pixel corner error: laterally it weighs z * sigma / f, more than depth far away."""


@dataclass
class Corners3D:
    """``points_m``: (N, 3) camera-frame corners (NaN where depth was missing);
    ``weights``: (N,) inverse variance of each corner's position (depth from the local plane
    fit, lateral from the corner's pixel error at its distance), 0 where missing."""

    points_m: NDArray[np.float64]
    weights: NDArray[np.float64]

    @property
    def valid(self) -> NDArray[np.bool_]:
        return np.isfinite(self.points_m).all(axis=1) & (self.weights > 0)


def rays(pixels: NDArray[np.floating], intrinsics: Intrinsics) -> NDArray[np.float64]:
    """(N, 3) viewing rays (z = 1) of pixel positions (N, 2), undistorted."""
    normalised = cv2.undistortPoints(
        np.asarray(pixels, np.float64).reshape(-1, 1, 2),
        intrinsics.K,
        np.array(intrinsics.distortion, np.float64),
    ).reshape(-1, 2)
    return np.column_stack([normalised, np.ones(len(normalised))])


def lift_corners(
    corners_px: NDArray[np.float32],
    depth_m: NDArray[np.float32],
    intrinsics: Intrinsics,
    radius_px: int = 4,
) -> Corners3D:
    """3D corners from 2D corners (N, 2) and the registered depth image (H, W) in metres."""
    points = np.full((len(corners_px), 3), np.nan)
    weights = np.zeros(len(corners_px))
    corner_rays = rays(corners_px, intrinsics)
    offsets = np.mgrid[-radius_px : radius_px + 1, -radius_px : radius_px + 1].reshape(2, -1).T
    for i, (u, v) in enumerate(np.rint(corners_px).astype(int)):
        pixels = offsets + np.array([u, v])
        inside = (
            (pixels[:, 0] >= 0)
            & (pixels[:, 0] < depth_m.shape[1])
            & (pixels[:, 1] >= 0)
            & (pixels[:, 1] < depth_m.shape[0])
        )
        pixels = pixels[inside]
        z = depth_m[pixels[:, 1], pixels[:, 0]].astype(np.float64)
        good = np.isfinite(z) & (z > 0)
        if good.sum() < MIN_PLANE_PIXELS:
            continue
        window = rays(pixels[good], intrinsics) * z[good, None]
        plane = _robust_plane(window)
        if plane is None:
            continue
        normal, offset, sigma_m = plane
        denominator = float(normal @ corner_rays[i])
        if abs(denominator) < 1e-6:
            continue
        points[i] = corner_rays[i] * (offset / denominator)
        lateral_m = points[i, 2] * CORNER_SIGMA_PX / min(intrinsics.fx, intrinsics.fy)
        weights[i] = 1.0 / (sigma_m**2 / good.sum() + 2.0 * lateral_m**2)
    return Corners3D(points, weights)


def _robust_plane(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], float, float] | None:
    """Plane n.x = d through (N, 3) points, refitted once without points beyond 3 MADs;
    returns (n, d, residual sigma in metres)."""
    keep = np.ones(len(points), bool)
    for _ in range(2):
        if keep.sum() < MIN_PLANE_PIXELS:
            return None
        centre = points[keep].mean(axis=0)
        normal = np.linalg.svd(points[keep] - centre, full_matrices=False)[2][2]
        residuals = (points - centre) @ normal
        mad = float(np.median(np.abs(residuals[keep] - np.median(residuals[keep])))) + 1e-6
        keep = np.abs(residuals) <= 3.0 * 1.4826 * mad
    sigma = float(np.std(residuals[keep]))
    return normal, float(normal @ centre), max(sigma, 1e-4)
