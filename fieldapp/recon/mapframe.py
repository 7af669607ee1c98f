"""Plot coordinates: the reconstruction's field frame turned and shifted onto the base's map.

The session-format spec asks that, when the captures carry ``base_pose`` or the session a
``plan`` with the stations' map poses, the field frame's x and y are the map's: an agronomist
finds plant 7 at the map position the table says. The base reports where it stands (its origin
is on the ground under the turntable axis); registration says where each station's turntable
axis stands in the field frame. A 2-D rigid fit (Kabsch) of the stations' axes onto their map
positions gives ``T_map_field``: a turn about z and a shift in x and y, z unchanged (z = 0 stays
on the ground). With one station only, its yaw is used: view 0 looks along the base's x axis.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from devices.geometry import (
    Matrix4,
    fit_plan_motion,
    make_transform,
    rotation_z,
    transform_points,
)
from fieldapp.io.session import Session, reported_base_poses
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.grid import GridNodes, plan_nodes
from fieldapp.recon.register import StationRegistration


def station_map_poses(session: Session) -> dict[int, tuple[float, float, float]]:
    """Per station, the map pose (x_m, y_m, yaw_deg) the base reported at it (mean over its
    captures), else the plan's pose for it; empty when the session has neither."""
    poses = reported_base_poses(session)
    plan = session.document.plan
    if plan is not None:
        for planned in plan.stations:
            poses.setdefault(planned.number, (planned.x_m, planned.y_m, planned.yaw_deg))
    return poses


def fit_T_map_field(
    field_xy_m: NDArray[np.float64],
    map_xy_m: NDArray[np.float64],
    field_heading_deg: float,
    map_yaw_deg: float,
) -> Matrix4:
    """The 2-D rigid ``T_map_field`` taking ``field_xy_m`` (S, 2) onto ``map_xy_m`` (S, 2); with
    one station the turn is ``map_yaw_deg - field_heading_deg`` (its view 0's heading)."""
    if len(field_xy_m) >= 2:
        return fit_plan_motion(field_xy_m, map_xy_m)
    R = rotation_z(map_yaw_deg - field_heading_deg)
    return make_transform(R, np.append(map_xy_m[0] - R[:2, :2] @ field_xy_m[0], 0.0))


def turntable_axis_direction(T_view_next: Matrix4) -> NDArray[np.float64]:
    """(3,) the unit direction of the turntable's axis in the camera frame: the axis of the view
    step's rotation."""
    R = T_view_next[:3, :3]
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    norm = float(np.linalg.norm(axis))
    return axis / norm if norm > 1e-12 else np.array([0.0, -1.0, 0.0])


def map_alignment(
    poses: dict[int, tuple[float, float, float]],
    T_field_station: dict[int, Matrix4],
    axis_point_camera: NDArray[np.float64],
    axis_direction_camera: NDArray[np.float64] | None = None,
) -> Matrix4 | None:
    """``T_map_field`` from the stations placed (view 0 in the field frame) that have a map
    pose; ``None`` when none has. Each station's turntable axis is followed down to the ground
    (z = 0): a base standing on sloping soil tilts its axis, and the camera-height point of a
    1 degree tilt is 2 cm off the base's position."""
    stations = sorted(set(poses) & set(T_field_station))
    if not stations:
        return None
    field_xy = np.array(
        [
            _axis_foot_xy(T_field_station[s], axis_point_camera, axis_direction_camera)
            for s in stations
        ]
    )
    map_xy = np.array([poses[s][:2] for s in stations])
    forward = T_field_station[stations[0]][:3, 2]
    heading_deg = float(np.degrees(np.arctan2(forward[1], forward[0])))
    return fit_T_map_field(field_xy, map_xy, heading_deg, poses[stations[0]][2])


def _axis_foot_xy(
    T_field_camera: Matrix4,
    point_camera: NDArray[np.float64],
    direction_camera: NDArray[np.float64] | None,
) -> NDArray[np.float64]:
    """(2,) where the turntable axis meets the ground (z = 0), in the field frame."""
    point = T_field_camera[:3, :3] @ point_camera + T_field_camera[:3, 3]
    if direction_camera is None:
        return point[:2]
    direction = T_field_camera[:3, :3] @ direction_camera
    if abs(direction[2]) < 0.5:  # not a near-vertical axis: keep the point
        return point[:2]
    return (point - direction * (point[2] / direction[2]))[:2]  # type: ignore[no-any-return]


def in_map_frame(
    T_map_field: Matrix4,
    cloud: Cloud,
    soil_m: NDArray[np.float64],
    registrations: dict[int, StationRegistration],
) -> tuple[Cloud, NDArray[np.float64], dict[int, StationRegistration]]:
    """The plot's cloud, soil sample and station placements with the map's x and y."""
    placed = {
        s: replace(r, T_field_station=T_map_field @ r.T_field_station)
        for s, r in registrations.items()
    }
    return cloud.transformed(T_map_field), transform_points(T_map_field, soil_m), placed


def session_grid(
    session: Session, T_map_field: Matrix4 | None, warnings: list[str]
) -> tuple[GridNodes | None, int | None]:
    """The session's planting grid in the output frame and the number of plants it expects;
    ``(None, None)`` without one (a warning when it cannot be placed: no map poses)."""
    plan = session.document.plan
    grid = plan.planting_grid if plan is not None else None
    if grid is None:
        return None, None
    if T_map_field is None:
        warnings.append("planting grid not used: the session has no map poses to place it")
        return None, None
    nodes = plan_nodes(grid, np.eye(4))  # the output frame is the map's
    return nodes, grid.expected_plants
