"""Levelling the stations: the field frame from the calibration's ground (or the reference
station's own ground), then each station corrected onto the ground it sees."""

from __future__ import annotations

import logging

import numpy as np

from devices.geometry import Matrix4, invert, rotation_angle_deg, transform_points
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration
from fieldapp.recon.ground import (
    GroundNotFound,
    T_field_camera_from_plane,
    fit_ground_plane,
    level_station,
    subsample,
)
from fieldapp.recon.scans import StationScan
from fieldapp.recon.settings import GroundSettings

log = logging.getLogger(__name__)

CAMERA_UP = np.array([0.0, -1.0, 0.0])
"""Up in a camera frame (OpenCV: y points down) when the camera stands upright."""
MAX_CAMERA_PITCH_DEG = 80.0
"""How far from its own "up" the ground's normal may be in an upright camera looking down."""


def T_field_reference_initial(
    calibration: Calibration, scan: StationScan, settings: GroundSettings
) -> Matrix4:
    """The transform from the calibration's reference frame to the field frame: the
    calibration's ``ground.matrix`` when given, else found in ``scan`` (the anchoring
    station) by RANSAC: origin below its camera, x along its forward direction."""
    if calibration.ground is not None:
        return calibration.ground.matrix
    if calibration.stations is None:
        raise FieldappError("the calibration has no stations")
    points = subsample(scan.soil.points, settings.sample_points)
    try:
        plane = fit_ground_plane(
            points,
            settings.ransac_distance_m,
            settings.ransac_iterations,
            CAMERA_UP,
            MAX_CAMERA_PITCH_DEG,
        )
    except GroundNotFound as error:
        raise FieldappError(f"station {scan.station}: no ground found ({error})") from None
    T_field_station = T_field_camera_from_plane(plane)
    return T_field_station @ invert(calibration.stations.to_reference[scan.station])


def level_stations(
    scans: dict[int, StationScan],
    T_field_coarse: dict[int, Matrix4],
    settings: GroundSettings,
) -> tuple[dict[int, Matrix4], list[str]]:
    """Each station's placement corrected so that the ground it sees is z = 0, level, and the
    warnings.

    A station whose ground cannot be found keeps its coarse placement (with a warning).
    """
    levelled, warnings = {}, []
    for station, scan in scans.items():
        points = transform_points(
            T_field_coarse[station], subsample(scan.soil.points, settings.sample_points)
        )
        try:
            T_correction, plane = level_station(
                points,
                settings.ransac_distance_m,
                settings.ransac_iterations,
                settings.search_band_m,
                settings.max_tilt_deg,
            )
        except GroundNotFound as error:
            warnings.append(f"station {station}: ground not found ({error}); not levelled")
            levelled[station] = T_field_coarse[station]
            continue
        log.debug(
            "station %d levelled by %.2f deg, %.1f mm",
            station,
            rotation_angle_deg(T_correction[:3, :3]),
            plane.offset_m * 1000,
        )
        levelled[station] = T_correction @ T_field_coarse[station]
    return levelled, warnings
