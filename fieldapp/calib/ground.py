"""Ground calibration: the field frame (z up, 0 on the ground) from the reference station's
ground plane, found by RANSAC in every view of that station joined by the view step.

``ground.matrix`` is ``T_field_reference``: it maps the reference station's view-0 camera frame
into the field frame. The field frame's origin lies under that camera, its x axis along the
camera's forward direction on the ground (as the reconstruction does without it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert, transform_points
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration
from fieldapp.io.session import Session
from fieldapp.recon.backproject import backproject, ray_table
from fieldapp.recon.ground import (
    GroundNotFound,
    Plane,
    T_field_camera_from_plane,
    fit_ground_plane,
    subsample,
)
from fieldapp.recon.levelling import CAMERA_UP, MAX_CAMERA_PITCH_DEG
from fieldapp.recon.settings import ReconstructionSettings

MIN_INLIER_FRACTION = 0.3
"""Below this share of the points on the plane, the plane found is not trusted."""
CHANGE_WARNING_M = 0.05
CHANGE_WARNING_DEG = 2.0
"""A new ground this far from the one in force is worth a second look."""


@dataclass
class GroundResult:
    """The ground seen from ``station`` and the field frame it gives."""

    station: int
    T_field_reference: Matrix4
    plane: Plane
    """In the station's view-0 camera frame."""
    points: int
    """Points the plane was fitted to (all views of the station, subsampled)."""
    inlier_fraction: float
    rms_m: float
    """RMS distance of the plane's inliers to it."""
    camera_height_m: float
    """Height of the view-0 camera above the ground."""
    camera_pitch_deg: float
    """Angle of the optical axis below the horizon (positive: looking down)."""
    change_from_previous: tuple[float, float] | None = None
    """How far the ground moved from the calibration's, if any: (height change of the
    reference camera in metres, tilt between the two ground normals in degrees)."""
    warnings: list[str] = field(default_factory=list)


def station_points_m(
    session: Session, calibration: Calibration, station: int, settings: ReconstructionSettings
) -> NDArray[np.float64]:
    """(N, 3) points of every view of ``station`` in its view-0 frame (subsampled)."""
    if calibration.view_step is None:
        raise FieldappError("the calibration has no view_step: calibrate the views first")
    captures = [c for c in session.captures if c.station == station and c.key[2] is None]
    captures = captures or [c for c in session.captures if c.station == station]
    if not captures:
        raise FieldappError(f"{session.folder}: no capture of station {station}")
    rays = ray_table(calibration.depth_camera.intrinsics())
    per_view = max(settings.ground.sample_points // len(captures), 1)
    crop = settings.crop
    parts = []
    for capture in captures:
        images = session.read_capture(capture)
        cloud = backproject(images.depth_m, images.color, rays, crop.radius_m, crop.min_depth_m)
        T_view0_view = calibration.view_step.T_view0_view(capture.view)
        parts.append(transform_points(T_view0_view, subsample(cloud.points, per_view)))
    return np.concatenate(parts)


def calibrate_ground(
    session: Session,
    calibration: Calibration,
    settings: ReconstructionSettings | None = None,
    station: int | None = None,
) -> GroundResult:
    """The field frame from the ground seen at ``station`` (default: the reference station of
    ``calibration``, whose view step joins the views). Raises :class:`FieldappError` when the
    station is not calibrated or no level ground is found."""
    settings = settings or ReconstructionSettings()
    if calibration.stations is None:
        raise FieldappError("the calibration has no stations: calibrate the stations first")
    station = calibration.stations.reference if station is None else station
    if station not in calibration.stations.to_reference:
        raise FieldappError(f"station {station} has no to_reference calibration")
    points = station_points_m(session, calibration, station, settings)
    ground = settings.ground
    try:
        plane = fit_ground_plane(
            points, ground.ransac_distance_m, ground.ransac_iterations, CAMERA_UP,
            MAX_CAMERA_PITCH_DEG,
        )  # fmt: skip
    except GroundNotFound as error:
        raise FieldappError(f"station {station}: no ground found ({error})") from None
    if plane.inlier_fraction < MIN_INLIER_FRACTION:
        raise FieldappError(
            f"station {station}: only {100 * plane.inlier_fraction:.0f} % of the points lie on "
            "the ground plane found: clear the view of objects, or point the camera down more"
        )
    T_reference_station = calibration.stations.to_reference[station]
    return _result(
        calibration, station, points, plane, T_reference_station, ground.ransac_distance_m
    )


def _result(
    calibration: Calibration,
    station: int,
    points: NDArray[np.float64],
    plane: Plane,
    T_reference_station: Matrix4,
    distance_m: float,
) -> GroundResult:
    T_field_reference = T_field_camera_from_plane(plane) @ invert(T_reference_station)
    heights = plane.height_m(points)
    inliers = heights[np.abs(heights) <= distance_m]
    forward = np.array([0.0, 0.0, 1.0])
    pitch_deg = float(np.degrees(np.arcsin(np.clip(-(forward @ plane.normal), -1.0, 1.0))))
    result = GroundResult(
        station=station,
        T_field_reference=T_field_reference,
        plane=plane,
        points=len(points),
        inlier_fraction=plane.inlier_fraction,
        rms_m=float(np.sqrt(np.mean(inliers**2))) if len(inliers) else 0.0,
        camera_height_m=float(plane.offset_m),
        camera_pitch_deg=pitch_deg,
    )
    if calibration.ground is not None:
        moved_m, turned_deg = ground_change(T_field_reference, calibration.ground.matrix)
        result.change_from_previous = (moved_m, turned_deg)
        if moved_m > CHANGE_WARNING_M or turned_deg > CHANGE_WARNING_DEG:
            result.warnings.append(
                f"the ground moved {100 * moved_m:.0f} cm and {turned_deg:.1f} degrees from the "
                "calibration in force: was the camera mount or the base changed?"
            )
    return result


def ground_change(
    T_field_reference: Matrix4, T_field_reference_before: Matrix4
) -> tuple[float, float]:
    """(camera height change in metres, tilt between the ground normals in degrees): what two
    ground calibrations disagree on, whatever origin and heading each field frame chose."""
    up, up_before = T_field_reference[2, :3], T_field_reference_before[2, :3]
    tilt_deg = float(np.degrees(np.arccos(np.clip(up @ up_before, -1.0, 1.0))))
    return abs(float(T_field_reference[2, 3] - T_field_reference_before[2, 3])), tilt_deg
