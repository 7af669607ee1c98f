"""Scenes for the calibration workflows.

- Intrinsics: a board held at varied poses close to the camera, covering the image, in front of
  a dim wall (IR images, as the paper calibrates from).
- View step: a board standing near the reference station, seen by both views 0 and 1.
- Stations: a board lying on the soil midway between each pair of neighbouring stations, seen
  from both.

The view-step and station boards are 9 x 6 inner corners by default (asymmetric); ``corners``
sets another size, e.g. (7, 5): the symmetric board of the public Kinect v2 calibration sets.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import KINECT_V2_PAPER, Frame, Intrinsics
from devices.geometry import (
    Matrix4,
    make_transform,
    rotation_x,
    rotation_y,
    rotation_z,
    transform_points,
)
from devices.sim.boards import Checkerboard, PlacedBoard, board_facing, board_lying
from devices.sim.render import Renderer, SensorModel
from devices.sim.rig import REFERENCE_STATION, RigGeometry
from devices.sim.scene import Body, Scene, empty_scene
from devices.sim.soil import Soil
from devices.sim.visibility import project

INTRINSICS_BOARD = Checkerboard("intrinsics", inner_cols=9, inner_rows=6, square_m=0.04)
VIEW_STEP_BOARD = Checkerboard("view-step", inner_cols=9, inner_rows=6, square_m=0.05)
DEFAULT_CORNERS = (9, 6)
WALL_DISTANCE_M = 3.0
VIEW_STEP_DISTANCE_M = 1.1
"""How far the view-step board stands from the camera, along the bisector of views 0 and 1."""
SIDE_OFFSET_M = 0.15
"""Station boards lie this far to the right of the line between their stations, clear of the
view-step board's shadow in the line of sight."""


def neighbour_pairs() -> list[tuple[int, int]]:
    """Neighbouring stations of the 3 x 3 grid (along rows, then along columns)."""
    pairs = [(s, s + 1) for s in range(1, 10) if s % 3 != 0]
    return pairs + [(s, s + 3) for s in range(1, 7)]


def station_board(a: int, b: int, corners: tuple[int, int] = DEFAULT_CORNERS) -> Checkerboard:
    return Checkerboard(
        f"stations-{a}-{b}", inner_cols=corners[0], inner_rows=corners[1], square_m=0.04
    )


def view_step_board(corners: tuple[int, int] = DEFAULT_CORNERS) -> Checkerboard:
    return replace(VIEW_STEP_BOARD, inner_cols=corners[0], inner_rows=corners[1])


def add_calibration_boards(
    scene: Scene, rig: RigGeometry, seed: int, corners: tuple[int, int] = DEFAULT_CORNERS
) -> None:
    """The view-step board near the reference station (standing, facing the camera between
    views 0 and 1) and one board between each pair of neighbouring stations (lying on the soil,
    short side towards the stations); ``corners`` (cols, rows) inner corners each."""
    if scene.soil is None:
        raise ValueError("the calibration boards stand on soil")
    rng = np.random.default_rng([seed, 23])
    reference = rig.station_pose(REFERENCE_STATION)
    T_camera = rig.T_field_camera(reference, rig.view_step_deg / 2, scene.soil)
    centre = transform_points(T_camera, np.array([[0.0, 0.0, VIEW_STEP_DISTANCE_M]]))[0]
    standing = view_step_board(corners)
    scene.add_board(PlacedBoard(standing, board_facing(standing, centre, T_camera[:3, 3])))
    for a, b in neighbour_pairs():
        pa, pb = rig.station_pose(a), rig.station_pose(b)
        mid_map = np.array([(pa.x_m + pb.x_m) / 2, (pa.y_m + pb.y_m) / 2, 0.0])
        heading_rad = np.arctan2(pb.y_m - pa.y_m, pb.x_m - pa.x_m)
        right = np.array([np.sin(heading_rad), -np.cos(heading_rad), 0.0])
        mid = transform_points(rig.T_field_map, (mid_map + SIDE_OFFSET_M * right)[None, :])[0]
        mid[2] = scene.soil.height_at(mid[0], mid[1])
        board = station_board(a, b, corners)
        # x across the line, so the short side points at the stations
        yaw = np.degrees(heading_rad) + 90.0 + rng.uniform(-8.0, 8.0)
        T = board_lying(board, mid, yaw, _ground_normal(scene.soil, mid[0], mid[1]))
        scene.add_board(PlacedBoard(board, _rest_on(scene.soil, board, T)))


def _rest_on(soil: Soil, board: Checkerboard, T_field_board: Matrix4) -> Matrix4:
    """``T_field_board`` lifted so the whole sheet clears the soil's bumps (by 2 mm)."""
    x0, x1, y0, y1 = board.outline_m
    gx, gy = np.meshgrid(np.linspace(x0, x1, 25), np.linspace(y0, y1, 25))
    sheet = transform_points(T_field_board, np.stack([gx.ravel(), gy.ravel(), 0 * gx.ravel()], 1))
    lift = float(np.max(soil.height_m(sheet[:, 0], sheet[:, 1]) - sheet[:, 2])) + 0.002
    lifted = T_field_board.copy()
    lifted[2, 3] += lift
    return lifted


def _ground_normal(soil: Soil, x: float, y: float, step_m: float = 0.2) -> NDArray[np.float64]:
    h = soil.height_at
    gx = (h(x + step_m, y) - h(x - step_m, y)) / (2 * step_m)
    gy = (h(x, y + step_m) - h(x, y - step_m)) / (2 * step_m)
    normal = np.array([-gx, -gy, 1.0])
    return normal / np.linalg.norm(normal)  # type: ignore[no-any-return]


def checkerboard_scene(
    seed: int, rig: RigGeometry, corners: tuple[int, int] = DEFAULT_CORNERS
) -> Scene:
    """Bare soil with the calibration boards of :func:`add_calibration_boards`."""
    scene = empty_scene(seed)
    add_calibration_boards(scene, rig, seed, corners)
    return scene


def intrinsics_poses(
    board: Checkerboard, intrinsics: Intrinsics, count: int, seed: int, margin_px: float = 15.0
) -> list[Matrix4]:
    """``count`` poses ``T_camera_board`` of ``board`` 0.5-0.85 m from the camera, tilted up to
    40 degrees, spread over a grid of image positions, each with all corners inside the image."""
    rng = np.random.default_rng([seed, 29])
    poses: list[Matrix4] = []
    cells = [(c, r) for r in range(4) for c in range(5)]
    while len(poses) < count:
        c, r = cells[len(poses) % len(cells)]
        for _ in range(200):
            T = _random_pose(board, intrinsics, (c + 0.5) / 5, (r + 0.5) / 4, rng)
            if _fits(board, intrinsics, T, margin_px):
                poses.append(T)
                break
        else:
            cells[len(poses) % len(cells)] = (2, 2)  # corner too tight: use the centre instead
    return poses


def _random_pose(
    board: Checkerboard, intrinsics: Intrinsics, fu: float, fv: float, rng: np.random.Generator
) -> Matrix4:
    depth = rng.uniform(0.5, 0.85)
    u = intrinsics.width * (0.5 + 0.8 * (fu - 0.5))
    v = intrinsics.height * (0.5 + 0.8 * (fv - 0.5))
    centre = (
        np.array([(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, 1.0])
        * depth
    )
    tilt = (
        rotation_x(rng.uniform(-40, 40))
        @ rotation_y(rng.uniform(-40, 40))
        @ rotation_z(rng.uniform(-25, 25))
    )
    return make_transform(tilt, centre - tilt @ board.centre_m)


def _fits(
    board: Checkerboard, intrinsics: Intrinsics, T_camera_board: Matrix4, margin_px: float
) -> bool:
    x0, x1, y0, y1 = board.outline_m
    sheet = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])
    camera = transform_points(T_camera_board, sheet)
    if np.any(camera[:, 2] < 0.5):
        return False
    pixels = project(intrinsics, camera)
    return bool(
        np.all(pixels >= margin_px)
        and np.all(pixels[:, 0] <= intrinsics.width - 1 - margin_px)
        and np.all(pixels[:, 1] <= intrinsics.height - 1 - margin_px)
    )


def intrinsics_scene(board: Checkerboard, T_camera_board: Matrix4) -> Scene:
    """The board at ``T_camera_board`` before a wall ``WALL_DISTANCE_M`` away; the scene's field
    frame is the camera frame (render it from the identity)."""
    scene = Scene(soil=None)
    scene.add_board(PlacedBoard(board, T_camera_board))
    half = 4.0
    wall = np.array(
        [
            [-half, -half, WALL_DISTANCE_M],
            [half, -half, WALL_DISTANCE_M],
            [half, half, WALL_DISTANCE_M],
            [-half, half, WALL_DISTANCE_M],
        ]
    )
    triangles = np.array([[0, 2, 1], [0, 3, 2]], dtype=np.int32)
    scene.bodies.append(
        Body(
            "wall",
            "wall",
            wall,
            triangles,
            np.full((4, 3), 0.4, np.float32),
            np.full(4, 0.35, np.float32),
        )
    )
    return scene


def intrinsics_images(
    count: int,
    seed: int,
    intrinsics: Intrinsics = KINECT_V2_PAPER,
    board: Checkerboard = INTRINSICS_BOARD,
    supersample: int = 3,
) -> Iterator[tuple[Matrix4, NDArray[np.uint16]]]:
    """``count`` (``T_camera_board``, IR image (H, W) uint16) pairs of ``board`` held before the
    camera. The board's part of the image is rendered with ``supersample`` x ``supersample``
    rays per pixel (a real sensor integrates light over each pixel), the rest with one."""
    coarse = SensorModel(color=False)
    fine = SensorModel(supersample=supersample, color=False)
    for index, T_camera_board in enumerate(intrinsics_poses(board, intrinsics, count, seed)):
        scene = intrinsics_scene(board, T_camera_board)
        rng = np.random.default_rng([seed, 31, index])
        ir = _ir(Renderer(scene, intrinsics, coarse).render(np.eye(4), rng))
        u0, v0, u1, v1 = _sheet_box(board, intrinsics, T_camera_board)
        crop = replace(
            intrinsics, width=u1 - u0, height=v1 - v0, cx=intrinsics.cx - u0, cy=intrinsics.cy - v0
        )
        ir[v0:v1, u0:u1] = _ir(Renderer(scene, crop, fine).render(np.eye(4), rng))
        yield T_camera_board, ir


def _ir(frame: Frame) -> NDArray[np.uint16]:
    if frame.ir is None:
        raise ValueError("the renderer gave no IR image")
    return frame.ir


def _sheet_box(
    board: Checkerboard, intrinsics: Intrinsics, T_camera_board: Matrix4, pad_px: int = 3
) -> tuple[int, int, int, int]:
    """Pixel box (u0, v0, u1, v1), end exclusive, holding the board's sheet in the image."""
    x0, x1, y0, y1 = board.outline_m
    sheet = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])
    pixels = project(intrinsics, transform_points(T_camera_board, sheet))
    u0, v0 = np.maximum(np.floor(pixels.min(axis=0)).astype(int) - pad_px, 0)
    u1, v1 = np.ceil(pixels.max(axis=0)).astype(int) + pad_px + 1
    return int(u0), int(v0), int(min(u1, intrinsics.width)), int(min(v1, intrinsics.height))
