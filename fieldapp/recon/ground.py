"""Levelling: find the ground plane by RANSAC and put the cloud in the field frame.

Guard against taking a canopy for the ground: candidate planes must be near the expected
ground (a band around it and a bounded tilt when a prior is known), and a plane is scored by
its inliers minus the points clearly *below* it: the ground is the lowest dominant plane, so a
leaf layer with soil underneath always loses to the soil.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, make_transform

log = logging.getLogger(__name__)

BELOW_FACTOR = 3.0
"""A point counts as below a plane when it is this many RANSAC distances under it."""

SCORING_POINTS = 4000
"""Candidate planes are scored on at most this many points, then refined on all of them."""


class GroundNotFound(ValueError):
    """No plane satisfying the guards was found in the points given."""


@dataclass(frozen=True)
class Plane:
    """``normal . p + offset_m = 0``; ``normal`` (3,) unit vector pointing up (into the air)."""

    normal: NDArray[np.float64]
    offset_m: float
    inlier_fraction: float

    def height_m(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Signed height of ``points`` (N, 3) above the plane, (N,)."""
        return points @ self.normal + self.offset_m


def least_squares_plane(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """The plane through ``points`` (N, 3) closest in the least squares: its unit normal and
    offset, a point's height ``points @ normal + offset`` (the normal's sign as it falls)."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    normal = vt[2]
    return normal, float(-normal @ centroid)


def _candidates(points: NDArray[np.float64], count: int, rng: np.random.Generator) -> NDArray[Any]:
    triples = points[rng.integers(0, len(points), size=(count, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    good = lengths > 1e-12
    normals = normals[good] / lengths[good, None]
    offsets = -np.einsum("ij,ij->i", normals, triples[good, 0])
    return np.concatenate([normals, offsets[:, None]], axis=1)


def fit_ground_plane(
    points: NDArray[np.float64],
    distance_m: float,
    iterations: int,
    up: NDArray[np.float64],
    max_tilt_deg: float = 90.0,
    seed: int = 0,
) -> Plane:
    """The lowest dominant plane of ``points`` (N, 3) whose normal is within ``max_tilt_deg``
    of ``up`` (3,); its normal is returned pointing along ``up``. Raises :class:`GroundNotFound`.
    """
    if len(points) < 3:
        raise GroundNotFound(f"only {len(points)} points to find the ground in")
    rng = np.random.default_rng(seed)
    planes = _candidates(points, iterations, rng)
    flip = planes[:, :3] @ up < 0
    planes[flip] *= -1.0
    planes = planes[planes[:, :3] @ up >= np.cos(np.radians(max_tilt_deg))]
    if len(planes) == 0:
        raise GroundNotFound(f"no plane within {max_tilt_deg:g} degrees of level")
    scoring = subsample(points, SCORING_POINTS, seed)
    heights = scoring @ planes[:, :3].T + planes[:, 3]  # (n, planes)
    inliers = np.abs(heights) <= distance_m
    below = heights < -BELOW_FACTOR * distance_m
    score = inliers.sum(axis=0) - below.sum(axis=0)
    best = int(np.argmax(score))
    normal, offset = least_squares_plane(scoring[inliers[:, best]])
    if normal @ up < 0:
        normal, offset = -normal, -offset
    final = np.abs(points @ normal + offset) <= distance_m
    normal, offset = least_squares_plane(points[final])
    if normal @ up < 0:
        normal, offset = -normal, -offset
    return Plane(normal, offset, float(final.mean()))


def T_level(plane: Plane) -> Matrix4:
    """The correction that turns ``plane`` (in some frame) into z = 0 with z up.

    The smallest rotation taking the plane's normal to +z, about the origin, then a shift in z.
    """
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(plane.normal, z)
    sin_angle = float(np.linalg.norm(axis))
    cos_angle = float(plane.normal @ z)
    if sin_angle < 1e-12:
        R = np.eye(3)
    else:
        k = axis / sin_angle
        K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        R = np.eye(3) + sin_angle * K + (1.0 - cos_angle) * (K @ K)
    return make_transform(R, np.array([0.0, 0.0, plane.offset_m]))


def T_field_camera_from_plane(plane: Plane) -> Matrix4:
    """The field frame when no prior is given, from the ground ``plane`` in a camera frame:
    origin below the camera, z up, x along the camera's forward direction on the ground."""
    z_axis = plane.normal
    forward = np.array([0.0, 0.0, 1.0]) - (plane.normal[2]) * plane.normal
    if np.linalg.norm(forward) < 1e-6:  # looking straight down: use the image's right
        forward = np.array([1.0, 0.0, 0.0]) - plane.normal[0] * plane.normal
    x_axis = forward / np.linalg.norm(forward)
    y_axis = np.cross(z_axis, x_axis)
    R_field_camera = np.stack([x_axis, y_axis, z_axis])
    return make_transform(R_field_camera, np.array([0.0, 0.0, plane.offset_m]))


def level_station(
    points_field: NDArray[np.float64],
    distance_m: float,
    iterations: int,
    search_band_m: float,
    max_tilt_deg: float,
    seed: int = 0,
) -> tuple[Matrix4, Plane]:
    """Refine a station's coarse placement in the field frame from its own ground.

    ``points_field``: (N, 3) the station's points placed by its coarse transform. Only points
    within ``search_band_m`` of z = 0 take part. Returns the correction ``T_field_fieldcoarse``
    and the plane found (in the coarse frame).
    """
    near = points_field[np.abs(points_field[:, 2]) <= search_band_m]
    up = np.array([0.0, 0.0, 1.0])
    plane = fit_ground_plane(near, distance_m, iterations, up, max_tilt_deg, seed)
    return T_level(plane), plane


def subsample(points: NDArray[np.float64], count: int, seed: int = 0) -> NDArray[np.float64]:
    """At most ``count`` of ``points`` (N, 3), drawn without replacement."""
    if len(points) <= count:
        return points
    rng = np.random.default_rng(seed)
    return points[rng.choice(len(points), size=count, replace=False)]
