"""The depth camera and rig of an import: intrinsics given on the command line or read from a
calibration file (fieldapp JSON or OpenCV YAML/XML), and a nominal single-station rig."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from devices.geometry import make_transform, rotation_y
from fieldapp.errors import FieldappError, FormatError
from fieldapp.io.calibration import (
    CALIBRATION_FORMAT,
    Calibration,
    DepthCamera,
    Stations,
    ViewStep,
    load_calibration,
)

IMPORT_STATION = 1
"""The station number of a single-station import."""


def parse_intrinsics(text: str, width: int, height: int, depth_scale: float) -> DepthCamera:
    """``"fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]"`` (pixels) for an image of ``width`` x ``height``."""
    try:
        values = [float(v) for v in text.replace(" ", "").split(",")]
    except ValueError:
        raise FieldappError(
            f"--intrinsics {text!r}: expected numbers fx,fy,cx,cy[,k1,k2,p1,p2,k3]"
        ) from None
    if len(values) not in (4, 8, 9) or not all(math.isfinite(v) for v in values):
        raise FieldappError(
            f"--intrinsics {text!r}: expected 4 numbers (fx,fy,cx,cy), or 8 or 9 with the "
            "distortion k1,k2,p1,p2[,k3]"
        )
    distortion = (values[4:] + [0.0] * 5)[:5] if len(values) > 4 else [0.0] * 5
    return _camera(values[:4], distortion, width, height, depth_scale, f"--intrinsics {text!r}")


def read_camera_file(path: Path, width: int, height: int, depth_scale: float) -> DepthCamera:
    """The depth camera of a fieldapp calibration (``.json``) or an OpenCV calibration
    (``.yml``/``.yaml``/``.xml`` with ``camera_matrix`` and ``distortion_coefficients``)."""
    if path.suffix.lower() == ".json":
        camera = load_calibration(path).depth_camera
        if (camera.width, camera.height) != (width, height):
            raise FieldappError(
                f"{path}: depth_camera is {camera.width} x {camera.height}, the depth images "
                f"are {width} x {height}"
            )
        return camera.model_copy(update={"depth_scale": depth_scale})
    return _opencv_camera(path, width, height, depth_scale)


def read_rig_file(path: Path) -> Calibration | None:
    """The calibration in a fieldapp JSON file, or ``None`` for an intrinsics-only format."""
    return load_calibration(path) if path.suffix.lower() == ".json" else None


def _opencv_camera(path: Path, width: int, height: int, depth_scale: float) -> DepthCamera:
    if not path.is_file():
        raise FieldappError(f"{path}: no such calibration file")
    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as error:
        raise FieldappError(f"{path}: not a readable OpenCV calibration file ({error})") from None
    try:
        K = _matrix(storage, ("camera_matrix", "K", "cameraMatrix"))
        dist = _matrix(storage, ("distortion_coefficients", "D", "distCoeffs", "dist"))
        size = [_scalar(storage, name) for name in ("image_width", "image_height")]
    finally:
        storage.release()
    if K is None or K.shape != (3, 3):
        raise FieldappError(f"{path}: no 3 x 3 camera_matrix")
    if None not in size and (size[0], size[1]) != (width, height):
        raise FieldappError(
            f"{path}: calibrated for {size[0]:g} x {size[1]:g} images, the depth images are "
            f"{width} x {height}"
        )
    distortion = [] if dist is None else [float(d) for d in dist.ravel()]
    if len(distortion) not in (0, 4, 5):
        raise FieldappError(f"{path}: distortion_coefficients must have 4 or 5 entries")
    intrinsics = [float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])]
    return _camera(intrinsics, (distortion + [0.0] * 5)[:5], width, height, depth_scale, str(path))


def _matrix(storage: cv2.FileStorage, names: tuple[str, ...]) -> NDArray[np.float64] | None:
    for name in names:
        node = storage.getNode(name)
        if not node.empty():
            matrix = node.mat()
            if matrix is not None:
                return np.asarray(matrix, np.float64)
    return None


def _scalar(storage: cv2.FileStorage, name: str) -> float | None:
    node = storage.getNode(name)
    return None if node.empty() else float(node.real())


def _camera(
    k: list[float],
    distortion: list[float],
    width: int,
    height: int,
    depth_scale: float,
    where: str,
) -> DepthCamera:
    fx, fy, cx, cy = k
    if not (fx > 0 and fy > 0 and 0 <= cx < width and 0 <= cy < height):
        raise FieldappError(
            f"{where}: fx {fx:g}, fy {fy:g} must be positive and the principal point "
            f"({cx:g}, {cy:g}) inside the {width} x {height} image"
        )
    return DepthCamera(
        width=width,
        height=height,
        fx=fx,
        fy=fy,
        cx=cx,
        cy=cy,
        distortion=distortion,
        depth_scale=depth_scale,
    )


def T_view_k_view_k1(step_deg: float, axis_distance_m: float) -> NDArray[np.float64]:
    """The nominal ``view_step.matrix`` of an upright, level camera and a table turning
    counter-clockwise (seen from above) by ``step_deg`` about a vertical axis.

    ``axis_distance_m`` 0: the camera turns on the table about its optical centre (this
    project's rig, the small offset ignored). Positive: the camera is fixed and the table (a
    plant on it) stands that far along the optical axis; the plant turning by +step is the
    camera orbiting the axis by -step.
    """
    if axis_distance_m == 0.0:
        return make_transform(rotation_y(-step_deg), np.zeros(3))
    centre = np.array([0.0, 0.0, axis_distance_m])
    R = rotation_y(step_deg)
    return make_transform(R, centre - R @ centre)


def import_calibration(
    camera: DepthCamera,
    step_deg: float,
    axis_distance_m: float,
    rig: Calibration | None,
) -> Calibration:
    """The calibration written with an import: ``rig``'s view step and stations when it has
    them, else a nominal single-station rig (marked ``nominal`` so nobody mistakes it)."""
    if rig is not None and rig.view_step is not None and rig.stations is not None:
        return rig.model_copy(update={"depth_camera": camera})
    view_step = ViewStep(angle_deg=step_deg, matrix=T_view_k_view_k1(step_deg, axis_distance_m))
    view_step.nominal = (
        f"fieldapp import: table turning {step_deg:g} degrees about a vertical axis "
        + (f"{axis_distance_m:g} m before the camera" if axis_distance_m else "through the camera")
        + "; not calibrated"
    )
    return Calibration(
        format=CALIBRATION_FORMAT,
        depth_camera=camera,
        view_step=view_step,
        stations=Stations(reference=IMPORT_STATION, to_reference={IMPORT_STATION: np.eye(4)}),
        ground=rig.ground if rig is not None else None,
    )


def camera_from_options(
    intrinsics: str | None,
    calibration: Path | None,
    width: int,
    height: int,
    depth_scale: float,
) -> DepthCamera:
    """The depth camera from ``--intrinsics`` or ``--calibration`` (exactly one)."""
    if (intrinsics is None) == (calibration is None):
        raise FieldappError(
            "give the depth camera's intrinsics: --intrinsics fx,fy,cx,cy or --calibration FILE "
            "(a fieldapp calibration.json or an OpenCV .yml/.xml), one of the two"
        )
    if intrinsics is not None:
        return parse_intrinsics(intrinsics, width, height, depth_scale)
    assert calibration is not None
    try:
        return read_camera_file(calibration, width, height, depth_scale)
    except FormatError as error:
        raise FieldappError(f"--calibration {calibration}:\n{error}") from None


def turntable_fields(axis_distance_m: float) -> dict[str, Any]:
    """``session.json``'s ``turntable`` entry for an import: a table axis in front of the camera
    (``axis_distance_m`` > 0) is a plant turning before a fixed camera, which the reconstruction
    handles apart (the room masked, the views placed about the axis)."""
    return {"turntable": {"carries": "plant"}} if axis_distance_m > 0 else {}
