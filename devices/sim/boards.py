"""Laser-printed checkerboards: geometry, poses and their printed pattern (visible in IR).

Board frame (OpenCV's object frame): origin at the first inner corner, x along the inner-corner
columns, y along the rows, z = x cross y pointing *into* the board. The printed face looks
towards -z, so a camera facing it sees x to the right and y down. Inner corner (i, j) is at
``(i * square_m, j * square_m, 0)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert, make_transform, transform_points
from devices.sim.linalg import apply

PAPER_RGB = np.array([0.92, 0.92, 0.90], dtype=np.float32)
TONER_RGB = np.array([0.04, 0.04, 0.04], dtype=np.float32)
PAPER_IR = 0.85
TONER_IR = 0.06
"""Laser toner (carbon) absorbs near-infrared; inkjet ink would not (invisible in IR)."""

BOARD_THICKNESS_M = 0.005


@dataclass(frozen=True)
class Checkerboard:
    """A board of ``inner_cols`` x ``inner_rows`` inner corners, ``square_m`` squares and a white
    margin of ``margin_squares`` squares around the pattern. 9 x 6 is not symmetric under a half
    turn, so its orientation is unambiguous."""

    name: str
    inner_cols: int = 9
    inner_rows: int = 6
    square_m: float = 0.04
    margin_squares: float = 1.0

    def __post_init__(self) -> None:
        if self.inner_cols < 2 or self.inner_rows < 2:
            raise ValueError(f"board {self.name}: needs at least 2 x 2 inner corners")
        if not self.square_m > 0:
            raise ValueError(f"board {self.name}: square_m must be positive")

    @property
    def object_points_m(self) -> NDArray[np.float64]:
        """(inner_cols * inner_rows, 3) inner corners in the board frame, row by row (OpenCV)."""
        i, j = np.meshgrid(np.arange(self.inner_cols), np.arange(self.inner_rows))
        points = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1)
        return points.astype(np.float64) * self.square_m

    @property
    def outline_m(self) -> tuple[float, float, float, float]:
        """Sheet edges in the board frame: x_min, x_max, y_min, y_max."""
        border = (1.0 + self.margin_squares) * self.square_m
        return (
            -border,
            (self.inner_cols - 1) * self.square_m + border,
            -border,
            (self.inner_rows - 1) * self.square_m + border,
        )

    @property
    def centre_m(self) -> NDArray[np.float64]:
        """(3,) centre of the pattern in the board frame."""
        return np.array(
            [
                (self.inner_cols - 1) * self.square_m / 2,
                (self.inner_rows - 1) * self.square_m / 2,
                0,
            ]
        )

    def is_black(self, xy_board_m: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether board-frame points (N, 2) fall on a printed (black) square."""
        cell = np.floor(xy_board_m / self.square_m).astype(np.int64)
        inside = (
            (cell[:, 0] >= -1)
            & (cell[:, 0] < self.inner_cols)
            & (cell[:, 1] >= -1)
            & (cell[:, 1] < self.inner_rows)
        )
        return inside & ((cell[:, 0] + cell[:, 1]) % 2 == 0)  # type: ignore[no-any-return]

    def mesh(self, T_field_board: Matrix4) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
        """Front sheet and back face (``BOARD_THICKNESS_M`` behind) as (V, 3), (T, 3) arrays."""
        x0, x1, y0, y1 = self.outline_m
        corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])
        back = corners + np.array([0.0, 0.0, BOARD_THICKNESS_M])
        vertices = transform_points(T_field_board, np.concatenate([corners, back]))
        triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]], dtype=np.int32)
        return vertices, triangles


@dataclass(frozen=True)
class PlacedBoard:
    """A board at ``T_field_board`` (maps board coordinates into the field frame)."""

    board: Checkerboard
    T_field_board: Matrix4

    def albedo(
        self, points_field_m: NDArray[np.floating]
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Colour (N, 3) 0-1 and NIR albedo (N,) at points on the board's printed face."""
        local = apply(invert(self.T_field_board), points_field_m)  # many points: no BLAS
        black = self.board.is_black(local[:, :2])
        rgb = np.where(black[:, None], TONER_RGB[None, :], PAPER_RGB[None, :])
        ir = np.where(black, TONER_IR, PAPER_IR).astype(np.float32)
        return rgb.astype(np.float32), ir

    @property
    def corners_field_m(self) -> NDArray[np.float64]:
        """(N, 3) inner corners in the field frame, OpenCV order."""
        return transform_points(self.T_field_board, self.board.object_points_m)


def board_facing(
    board: Checkerboard,
    centre_m: NDArray[np.float64],
    eye_m: NDArray[np.float64],
    roll_deg: float = 0.0,
) -> Matrix4:
    """``T_field_board`` putting the pattern's centre at ``centre_m`` with its printed face
    turned towards ``eye_m`` (both (3,) in the field frame), x as level as possible, then
    rolled by ``roll_deg`` about the board normal."""
    z_axis = np.asarray(centre_m, float) - np.asarray(eye_m, float)
    z_axis /= np.linalg.norm(z_axis)
    up = np.array([0.0, 0.0, 1.0]) if abs(z_axis[2]) < 0.95 else np.array([0.0, 1.0, 0.0])
    x_axis = np.cross(z_axis, up)
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    c, s = np.cos(np.radians(roll_deg)), np.sin(np.radians(roll_deg))
    x_axis, y_axis = c * x_axis + s * y_axis, -s * x_axis + c * y_axis
    R = np.stack([x_axis, y_axis, z_axis], axis=1)
    return make_transform(R, np.asarray(centre_m, float) - R @ board.centre_m)


def board_lying(
    board: Checkerboard,
    centre_m: NDArray[np.float64],
    yaw_deg: float,
    normal_up: NDArray[np.float64] | None = None,
) -> Matrix4:
    """``T_field_board`` for a board lying printed face up with its pattern centre at
    ``centre_m``, x at ``yaw_deg`` in the field frame, tilted to the local ground ``normal_up``."""
    n = np.array([0.0, 0.0, 1.0]) if normal_up is None else np.asarray(normal_up, float)
    n /= np.linalg.norm(n)
    heading = np.array([np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg)), 0.0])
    x_axis = heading - n * (heading @ n)
    x_axis /= np.linalg.norm(x_axis)
    z_axis = -n
    y_axis = np.cross(z_axis, x_axis)
    R = np.stack([x_axis, y_axis, z_axis], axis=1)
    return make_transform(R, np.asarray(centre_m, float) - R @ board.centre_m)
