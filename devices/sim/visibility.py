"""Which boards a camera sees whole: every inner corner in the image (with a margin), in
range, on the printed side, and not hidden behind anything else."""

from __future__ import annotations

import numpy as np
import open3d as o3d
from numpy.typing import NDArray

from devices.camera.frames import Intrinsics
from devices.geometry import Matrix4, invert, transform_points
from devices.sim.boards import PlacedBoard
from devices.sim.render import MAX_RANGE_M, MIN_RANGE_M, scene_raycaster, tensor
from devices.sim.scene import Scene

MARGIN_PX = 12.0
MIN_SQUARE_PX = 8.0
"""Squares smaller than this in the image are too small to detect reliably."""


def project(intrinsics: Intrinsics, points_camera_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N, 2) pixel coordinates of camera-frame points (N, 3) (pinhole, no distortion)."""
    z = points_camera_m[:, 2]
    u = intrinsics.fx * points_camera_m[:, 0] / z + intrinsics.cx
    v = intrinsics.fy * points_camera_m[:, 1] / z + intrinsics.cy
    return np.stack([u, v], axis=1)


def sees_board(
    scene: Scene,
    intrinsics: Intrinsics,
    T_field_camera: Matrix4,
    placed: PlacedBoard,
    margin_px: float = MARGIN_PX,
    raycaster: o3d.t.geometry.RaycastingScene | None = None,
) -> bool:
    """Whether the camera at ``T_field_camera`` sees every inner corner of ``placed``.

    ``raycaster``: the scene's bodies in order (built here when not given)."""
    corners = placed.corners_field_m
    camera = transform_points(invert(T_field_camera), corners)
    if np.any(camera[:, 2] < MIN_RANGE_M) or np.any(np.linalg.norm(camera, axis=1) > MAX_RANGE_M):
        return False
    pixels = project(intrinsics, camera)
    inside = (
        (pixels[:, 0] >= margin_px)
        & (pixels[:, 0] <= intrinsics.width - 1 - margin_px)
        & (pixels[:, 1] >= margin_px)
        & (pixels[:, 1] <= intrinsics.height - 1 - margin_px)
    )
    if not inside.all():
        return False
    if placed.board.square_m * intrinsics.fx / float(camera[:, 2].max()) < MIN_SQUARE_PX:
        return False
    normal_into_board = placed.T_field_board[:3, 2]
    eye = T_field_camera[:3, 3]
    if float(normal_into_board @ (corners.mean(axis=0) - eye)) <= 0.0:
        return False  # seen from behind
    raycaster = raycaster or scene_raycaster(scene)
    own = [
        i for i, b in enumerate(scene.bodies) if b.name == placed.board.name and b.kind == "board"
    ]
    return not _occluded(raycaster, eye, corners, own)


def _occluded(
    raycaster: o3d.t.geometry.RaycastingScene,
    eye: NDArray[np.float64],
    corners: NDArray[np.float64],
    own_ids: list[int],
) -> bool:
    """Whether anything but bodies ``own_ids`` lies between ``eye`` (3,) and ``corners`` (N, 3)."""
    towards = corners - eye
    rays = np.column_stack([np.tile(eye, (len(corners), 1)), towards]).astype(np.float32)
    result = raycaster.cast_rays(tensor(rays))
    t_hit = result["t_hit"].numpy()
    hidden = (t_hit < 0.995) & ~np.isin(result["geometry_ids"].numpy(), own_ids)
    return bool(hidden.any())


def boards_in_view(
    scene: Scene,
    intrinsics: Intrinsics,
    T_field_camera: Matrix4,
    raycaster: o3d.t.geometry.RaycastingScene | None = None,
) -> list[str]:
    """Names of the scene's boards seen whole from ``T_field_camera``."""
    if not scene.boards:
        return []
    raycaster = raycaster or scene_raycaster(scene)
    return [
        p.board.name
        for p in scene.boards
        if sees_board(scene, intrinsics, T_field_camera, p, raycaster=raycaster)
    ]
