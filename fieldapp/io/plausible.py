"""Physically possible calibrations: what no real depth camera or rig can have is refused.

The schema (``calibration.py``) checks types, signs and rigidity; a file can pass it and still
describe no camera at all (``fx = 1e308``, ``cx = -5``, ``depth_scale = 1e308``), and the
reconstruction would then measure nonsense without a word. The bounds below are general (a
Kinect v2, a RealSense, an Azure Kinect and a ToF module all sit well inside them) and are
documented in ``docs/FILES.md``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import Problem
from fieldapp.io.calibration import Calibration, DepthCamera
from fieldapp.io.images import MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE

FOV_RANGE_DEG = (3.0, 170.0)
"""Field of view along each image axis (a Kinect v2's depth camera: 70 x 60 degrees)."""
PIXEL_ASPECT_RANGE = (0.5, 2.0)
"""fy / fx (square pixels: 1)."""
DEPTH_SCALE_RANGE = (100.0, 100_000.0)
"""Units per metre: from 1 cm units to 10 micrometre units (Kinect v2: 1000, millimetres)."""
MAX_DISTORTION_SHIFT = 0.25
"""Largest shift the distortion model may apply inside the image, as a fraction of its
diagonal (a Kinect v2's factory model: about 0.03)."""
MIN_VIEW_STEP_DEG = 1.0
"""The turntable's step: at most 360 views per turn."""
MAX_TRANSLATION_M = {"view_step": 10.0, "stations": 100_000.0, "ground": 100_000.0}


def camera_problems(path: Path, camera: DepthCamera) -> list[Problem]:
    """Why ``camera`` cannot be a real depth camera (one problem per field), or nothing."""

    def problem(field: str, message: str) -> Problem:
        return Problem(str(path), f"depth_camera.{field}", message)

    size = _size_problems(camera)
    if size:
        return [problem(field, message) for field, message in size]
    problems = [problem(f, m) for f, m in _pinhole_problems(camera)]
    low, high = DEPTH_SCALE_RANGE
    if not low <= camera.depth_scale <= high:
        problems.append(
            problem(
                "depth_scale",
                f"{camera.depth_scale:g} units per metre is outside {low:g}-{high:g} "
                "(1000 = millimetres)",
            )
        )
    if not problems:
        distortion = _distortion_problem(camera)
        if distortion:
            problems.append(problem("distortion", distortion))
    return problems


def _size_problems(camera: DepthCamera) -> list[tuple[str, str]]:
    problems = []
    for name in ("width", "height"):
        value = getattr(camera, name)
        if value > MAX_IMAGE_SIDE:
            problems.append((name, f"{value} pixels is more than {MAX_IMAGE_SIDE}"))
    if not problems and camera.width * camera.height > MAX_IMAGE_PIXELS:
        problems.append(("width", f"{camera.width} x {camera.height} is over {MAX_IMAGE_PIXELS}"))
    return problems


def _fov_deg(side_px: int, focal_px: float) -> float:
    return math.degrees(2.0 * math.atan(side_px / (2.0 * focal_px)))


def _pinhole_problems(camera: DepthCamera) -> list[tuple[str, str]]:
    problems = []
    low, high = FOV_RANGE_DEG
    for focal, side, name in ((camera.fx, camera.width, "fx"), (camera.fy, camera.height, "fy")):
        fov = _fov_deg(side, focal)
        if not low <= fov <= high:
            problems.append(
                (
                    name,
                    f"{focal:g} px gives a {fov:.3g} degree field of view over {side} px "
                    f"(possible: {low:g}-{high:g})",
                )
            )
    aspect = camera.fy / camera.fx
    if not problems and not PIXEL_ASPECT_RANGE[0] <= aspect <= PIXEL_ASPECT_RANGE[1]:
        problems.append(("fy", f"fy / fx = {aspect:.3g}: pixels cannot be that far from square"))
    for centre, side, name in ((camera.cx, camera.width, "cx"), (camera.cy, camera.height, "cy")):
        if not 0.0 < centre < side:
            problems.append((name, f"principal point {centre:g} is outside the image (0-{side})"))
    return problems


def _distortion_problem(camera: DepthCamera) -> str | None:
    """Whether the distortion model stays finite, small and one-to-one over the image."""
    if not any(camera.distortion):
        return None
    K = np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1]], np.float64)
    import cv2  # here: the GUI loads sessions' calibrations at start-up without OpenCV

    rays = _rays_to_border(camera)  # (directions, steps, 2) ideal pixels
    shape = rays.shape
    with np.errstate(all="ignore"):
        ideal = np.column_stack(
            [
                (rays[..., 0].ravel() - camera.cx) / camera.fx,
                (rays[..., 1].ravel() - camera.cy) / camera.fy,
                np.ones(rays[..., 0].size),
            ]
        )
        projected, _ = cv2.projectPoints(
            ideal, np.zeros(3), np.zeros(3), K, np.asarray(camera.distortion, np.float64)
        )
        distorted = projected.reshape(shape)
        if not np.all(np.isfinite(distorted)):
            return "the model is not finite inside the image"
        diagonal = math.hypot(camera.width, camera.height)
        shift = float(np.max(np.linalg.norm(distorted - rays, axis=-1))) / diagonal
        radius = np.linalg.norm(distorted - [camera.cx, camera.cy], axis=-1)
    if shift > MAX_DISTORTION_SHIFT:
        return (
            f"moves points by {shift:.0%} of the image diagonal (possible: up to "
            f"{MAX_DISTORTION_SHIFT:.0%}; check the coefficients' order k1 k2 p1 p2 k3)"
        )
    if np.any(np.diff(radius, axis=1) <= 0.0):
        return "the model folds the image over on itself (not one-to-one)"
    return None


def _rays_to_border(
    camera: DepthCamera, directions: int = 32, steps: int = 24
) -> NDArray[np.float64]:
    """(directions, steps, 2) pixels on straight lines from the principal point to the border."""
    angles = np.linspace(0.0, 2 * np.pi, directions, endpoint=False)
    unit = np.column_stack([np.cos(angles), np.sin(angles)])
    with np.errstate(divide="ignore"):
        to_x = np.where(unit[:, 0] > 0, camera.width - camera.cx, -camera.cx) / unit[:, 0]
        to_y = np.where(unit[:, 1] > 0, camera.height - camera.cy, -camera.cy) / unit[:, 1]
    reach = np.minimum(np.abs(to_x), np.abs(to_y))
    fractions = np.linspace(1.0 / steps, 1.0, steps)
    offsets = unit[:, None, :] * (reach[:, None, None] * fractions[None, :, None])
    return offsets + np.array([camera.cx, camera.cy])  # type: ignore[no-any-return]


def calibration_problems(path: Path, calibration: Calibration) -> list[Problem]:
    """Everything physically impossible in ``calibration``: camera and rig translations."""
    problems = camera_problems(path, calibration.depth_camera)
    matrices: list[tuple[str, str, NDArray[np.float64]]] = []
    if calibration.view_step is not None:
        angle_deg = calibration.view_step.angle_deg
        if abs(angle_deg) < MIN_VIEW_STEP_DEG:
            problems.append(
                Problem(
                    str(path),
                    "view_step.angle_deg",
                    f"{angle_deg:g} degrees is less than a turntable's step can be "
                    f"({MIN_VIEW_STEP_DEG:g}: at most {round(360 / MIN_VIEW_STEP_DEG)} views)",
                )
            )
        matrices.append(("view_step", "view_step.matrix", calibration.view_step.matrix))
    if calibration.stations is not None:
        for station, matrix in calibration.stations.to_reference.items():
            matrices.append(("stations", f"stations.to_reference.{station}", matrix))
    if calibration.ground is not None:
        matrices.append(("ground", "ground.matrix", calibration.ground.matrix))
    for kind, field, matrix in matrices:
        # math.hypot scales: the norm's squares overflow from 1.3e154 m on (a fuzzed file)
        distance_m = math.hypot(*(float(value) for value in matrix[:3, 3]))
        if distance_m > MAX_TRANSLATION_M[kind]:
            problems.append(
                Problem(
                    str(path),
                    field,
                    f"translation of {distance_m:.3g} m is more than a rig can move "
                    f"({MAX_TRANSLATION_M[kind]:g} m)",
                )
            )
    return problems
