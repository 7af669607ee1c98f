"""Reading point clouds of other tools: PLY (:mod:`fieldapp.io.ply`), PCD, XYZ (Open3D) and
LAS/LAZ (laspy).

Every reader returns a :class:`~fieldapp.recon.cloud.Cloud` in metres with z up: ``units``
scales the file's coordinates, ``up`` names the file's up axis (``z``, ``y``, ``-y``...).
Points without colour get a neutral grey and ``has_color`` False.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError
from fieldapp.io import ply
from fieldapp.recon.cloud import Cloud

OPEN3D_SUFFIXES = {".pcd", ".xyz", ".xyzn", ".xyzrgb", ".pts"}
LAS_SUFFIXES = {".las", ".laz"}
CLOUD_SUFFIXES = OPEN3D_SUFFIXES | LAS_SUFFIXES | {".ply"}
UNITS_M = {"m": 1.0, "cm": 0.01, "mm": 0.001}
GREY = 128


@dataclass(frozen=True)
class LoadedCloud:
    cloud: Cloud
    has_color: bool


def up_rotation(up: str) -> NDArray[np.float64]:
    """(3, 3) rotation taking the file's ``up`` axis to +z (a right-handed frame kept)."""
    axes = {
        "z": np.eye(3),
        "-z": np.diag([1.0, -1.0, -1.0]),
        "y": np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]),
        "-y": np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]),
        "x": np.array([[0, 0, -1.0], [0, 1.0, 0], [1.0, 0, 0]]),
        "-x": np.array([[0, 0, 1.0], [0, 1.0, 0], [-1.0, 0, 0]]),
    }
    if up not in axes:
        raise FieldappError(f"--up {up!r}: one of {', '.join(axes)}")
    return axes[up]


def read_cloud(path: Path, units: str = "m", up: str = "z") -> LoadedCloud:
    """Read ``path`` by its suffix; raises :class:`FieldappError` naming the file."""
    if not path.is_file():
        raise FieldappError(f"{path}: no such file")
    if units not in UNITS_M:
        raise FieldappError(f"--units {units!r}: one of {', '.join(UNITS_M)}")
    suffix = path.suffix.lower()
    if suffix in LAS_SUFFIXES:
        points, colors = _read_las(path)
    elif suffix == ".ply":
        points, colors = _read_ply(path)
    elif suffix in OPEN3D_SUFFIXES:
        points, colors = _read_open3d(path)
    else:
        raise FieldappError(
            f"{path}: not a point cloud fieldapp reads (suffixes: "
            f"{', '.join(sorted(CLOUD_SUFFIXES))})"
        )
    finite = np.all(np.isfinite(points), axis=1)
    if not finite.any():
        raise FieldappError(f"{path}: holds no point")
    points = points[finite] * UNITS_M[units] @ up_rotation(up).T
    has_color = colors is not None
    rgb = colors[finite] if colors is not None else np.full(points.shape, GREY, np.uint8)
    return LoadedCloud(Cloud(np.ascontiguousarray(points), rgb), has_color)


def _read_ply(path: Path) -> tuple[NDArray[np.float64], NDArray[np.uint8] | None]:
    try:
        vertices = ply.read_ply(path)
        points = ply.points_of(vertices, str(path))
    except ply.PlyError as error:
        reason = str(error).removeprefix(f"{path}: ")
        raise FieldappError(f"{path}: no point read ({reason})") from None
    if len(points) == 0:
        raise FieldappError(f"{path}: no point read (not a point cloud, or empty)")
    return points, ply.colors_of(vertices)


def _read_open3d(path: Path) -> tuple[NDArray[np.float64], NDArray[np.uint8] | None]:
    import open3d as o3d

    cloud = o3d.io.read_point_cloud(path)
    points = np.asarray(cloud.points, np.float64)
    if len(points) == 0:
        raise FieldappError(f"{path}: no point read (not a point cloud, or empty)")
    if not cloud.has_colors():
        return points, None
    colors = np.clip(np.asarray(cloud.colors) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return points, colors


def _read_las(path: Path) -> tuple[NDArray[np.float64], NDArray[np.uint8] | None]:
    import laspy  # type: ignore[import-untyped, import-not-found, unused-ignore]

    try:
        data = laspy.read(path)
    except (laspy.errors.LaspyException, OSError, ValueError) as error:
        raise FieldappError(f"{path}: not a readable LAS/LAZ file ({error})") from None
    points = np.column_stack([np.asarray(data.x), np.asarray(data.y), np.asarray(data.z)])
    names = set(data.point_format.dimension_names)
    if not {"red", "green", "blue"} <= names:
        return points, None
    rgb = np.column_stack([np.asarray(data[c]) for c in ("red", "green", "blue")])
    if rgb.max(initial=0) > 255:  # LAS stores 16-bit colour
        rgb = rgb >> 8
    return points, rgb.astype(np.uint8)
