"""Depth to points: back-projection through a ray table, keeping colour, cropped to a radius.

The ray table holds, for every pixel, the direction (x/z, y/z, 1) of its ray in the camera frame
(OpenCV: x right, y down, z forward). With lens distortion the pixel is undistorted first, so a
point is simply ``depth * ray``: one multiply per pixel.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import Intrinsics
from fieldapp.io.calibration import Calibration
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.settings import CropSettings

PAPER_CAMERA_HEIGHT_M = 1.3
PAPER_STATION_SPACING_M = 1.6
"""The rig the paper's crop radius (2.25 m) was chosen for."""


def ray_table(intrinsics: Intrinsics) -> NDArray[np.float64]:
    """(H, W, 3) float64: the ray direction of every pixel with unit z (undistorted if needed)."""
    v, u = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width].astype(np.float64)
    if intrinsics.has_distortion:
        pixels = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
        distortion = np.asarray(intrinsics.distortion, dtype=np.float64)
        normalised = cv2.undistortPoints(pixels, intrinsics.K, distortion).reshape(
            intrinsics.height, intrinsics.width, 2
        )
        x, y = normalised[..., 0], normalised[..., 1]
    else:
        x = (u - intrinsics.cx) / intrinsics.fx
        y = (v - intrinsics.cy) / intrinsics.fy
    return np.stack([x, y, np.ones_like(x)], axis=-1)


def backproject(
    depth_m: NDArray[np.floating],
    color: NDArray[np.uint8],
    rays: NDArray[np.float64],
    crop_radius_m: float,
    min_depth_m: float = 0.0,
    pixels: NDArray[np.bool_] | None = None,
) -> Cloud:
    """The valid pixels of one frame as a coloured cloud in the camera frame.

    ``depth_m``: (H, W) metres along z, NaN or 0 where missing. ``color``: (H, W, 3) uint8 RGB
    registered to depth. ``rays``: from :func:`ray_table`. Points farther than ``crop_radius_m``
    from the optical centre, or nearer than ``min_depth_m`` in z, are dropped; with
    ``pixels`` (H, W) only those pixels are back-projected.
    """
    if depth_m.shape != rays.shape[:2] or color.shape[:2] != rays.shape[:2]:
        raise ValueError(
            f"depth {depth_m.shape} / colour {color.shape[:2]} do not match the camera "
            f"{rays.shape[:2]}"
        )
    measured = np.isfinite(depth_m)  # the depth limits are tested in float64, on fewer pixels
    if pixels is not None:
        measured &= pixels
    index = np.flatnonzero(measured)
    depth = depth_m.reshape(-1)[index]
    return backproject_pixels(
        index, depth, color.reshape(-1, 3)[index], rays, crop_radius_m, min_depth_m
    )


def backproject_pixels(
    index: NDArray[np.intp],
    depth_m: NDArray[np.floating],
    colors: NDArray[np.uint8],
    rays: NDArray[np.float64],
    crop_radius_m: float,
    min_depth_m: float = 0.0,
    mixed: NDArray[np.bool_] | None = None,
) -> Cloud:
    """Some pixels of one frame as a coloured cloud in the camera frame: the same points, in
    the same order, as :func:`backproject` of a mask holding those pixels.

    ``index``: (M,) the pixels' flat (row-major) indices, ascending; ``depth_m``: (M,) their
    depth in metres, measured (finite); ``colors``: (M, 3) uint8 RGB; ``mixed``: (M,) which are
    mixed pixels (:attr:`Cloud.mixed`). Only the pixels picked are gathered and multiplied, so
    a frame's few plant pixels cost little.
    """
    z = np.asarray(depth_m, dtype=np.float64)
    near = z > max(min_depth_m, 0.0)
    if not near.all():
        index, z, colors = index[near], z[near], colors[near]
        mixed = None if mixed is None else mixed[near]
    ray = np.take(rays.reshape(-1, 3), index, axis=0)  # three times faster than rays[index]
    points = ray * z[:, None]
    inside = _within_radius(ray, z, crop_radius_m)
    if inside.all():
        return Cloud(points, colors, mixed)
    return Cloud(
        np.compress(inside, points, axis=0),
        np.compress(inside, colors, axis=0),
        None if mixed is None else mixed[inside],
    )


def backproject_pixels_twice(
    index: NDArray[np.intp],
    depth_m: NDArray[np.floating],
    other_depth_m: NDArray[np.floating],
    colors: NDArray[np.uint8],
    rays: NDArray[np.float64],
    crop_radius_m: float,
    min_depth_m: float = 0.0,
    mixed: NDArray[np.bool_] | None = None,
) -> tuple[Cloud, Cloud]:
    """:func:`backproject_pixels` of the same pixels at two depths each (a frame's own and
    its blocks' medians, ``other_depth_m``), keeping a pixel in both clouds where the crop
    keeps it at both depths, so that the two are the same points, point for point; each
    ray gathered once for both."""
    z = np.asarray(depth_m, dtype=np.float64)
    other = np.asarray(other_depth_m, dtype=np.float64)
    ray = np.take(rays.reshape(-1, 3), index, axis=0)
    floor = max(min_depth_m, 0.0)
    keep = (z > floor) & (other > floor)
    keep &= _within_radius(ray, z, crop_radius_m) & _within_radius(ray, other, crop_radius_m)
    if not keep.all():
        ray, z, other, colors = ray[keep], z[keep], other[keep], colors[keep]
        mixed = None if mixed is None else mixed[keep]
    return Cloud(ray * z[:, None], colors, mixed), Cloud(ray * other[:, None], colors, mixed)


def _within_radius(
    ray: NDArray[np.float64], z: NDArray[np.float64], crop_radius_m: float
) -> NDArray[np.bool_]:
    """Which points ``ray * z`` lie within ``crop_radius_m`` of the camera."""
    return z * np.sqrt(ray[:, 0] ** 2 + ray[:, 1] ** 2 + 1.0) <= crop_radius_m


def rig_crop(crop: CropSettings, calibration: Calibration) -> CropSettings:
    """``crop`` with its radius scaled to the rig (``CropSettings.scale_to_rig``): the radius
    that keeps, on the ground, as many station spacings around each camera as ``radius_m``
    keeps on the paper's rig, and never less ground than it keeps there (the paper's rig keeps
    2.25 m: 1.84 m of ground, 1.15 of its 1.6 m spacings), to the centimetre. The cameras'
    height is the median of the stations' view-0 optical centres above the ground in the field
    frame of the calibration's ground transform, the spacing the median distance from each to
    the nearest other. ``crop`` as it is when the calibration has no ground transform or fewer
    than two stations (nothing to scale by), or when the radius does not reach the paper's
    ground.

    Stations farther apart need more ground for their clouds to overlap. Stations nearer
    together do not make the plot smaller: the outer plants stand as far beyond the outer
    stations, and their leaves reach out as far, so the ground kept is not cut below the
    paper's (an independent renderer's stations 0.8 m apart: 1.62-1.73 m kept 0.92 m of
    ground and cut the outer plants' leaves; its touching plots' width RMSE 2.6-27 cm, 2.4-3.5
    cm with the paper's ground). The registration need not see so far:
    :func:`overlap_radius`."""
    rig = _rig(crop, calibration)
    if rig is None:
        return crop
    height, spacing, ground_m = rig
    reach = max(ground_m, ground_m / PAPER_STATION_SPACING_M * spacing)
    return crop.model_copy(update={"radius_m": round(float(np.hypot(height, reach)), 2)})


def overlap_radius(crop: CropSettings, calibration: Calibration) -> float | None:
    """The radius (m) around each view's optical centre within which a station's points are
    registered, where it is less than :func:`rig_crop`'s: the paper's reach in station spacings
    alone, where stations stand nearer together than the paper's. Each station then overlaps
    its neighbours as on the paper's rig; with the whole of the paper's ground every station of
    a plot 0.8 m apart overlapped every other, and registration cost three times the CPU
    (`docs/RECONSTRUCTION.md`, "A sixth independent renderer"). ``None``: the whole crop."""
    rig = _rig(crop, calibration)
    if rig is None:
        return None
    height, spacing, ground_m = rig
    if spacing >= PAPER_STATION_SPACING_M:
        return None
    return round(float(np.hypot(height, ground_m / PAPER_STATION_SPACING_M * spacing)), 2)


def _rig(crop: CropSettings, calibration: Calibration) -> tuple[float, float, float] | None:
    """(the cameras' height, the stations' spacing, the ground the set radius keeps on the
    paper's rig) in metres, or ``None`` where the crop is not scaled (:func:`rig_crop`)."""
    stations = calibration.stations
    if not crop.scale_to_rig or calibration.ground is None or stations is None:
        return None
    if len(stations.to_reference) < 2 or crop.radius_m <= PAPER_CAMERA_HEIGHT_M:
        return None
    T_field_reference = calibration.ground.matrix
    centres = np.array([(T_field_reference @ T)[:3, 3] for T in stations.to_reference.values()])
    apart = np.linalg.norm(centres[:, None, :2] - centres[None, :, :2], axis=2)
    np.fill_diagonal(apart, np.inf)
    height, spacing = float(np.median(centres[:, 2])), float(np.median(apart.min(axis=1)))
    if height <= 0.0 or spacing <= 0.0:
        return None
    return height, spacing, float(np.sqrt(crop.radius_m**2 - PAPER_CAMERA_HEIGHT_M**2))
