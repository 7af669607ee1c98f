"""Checkerboards: their geometry and the detection of their inner corners in an image."""

from __future__ import annotations

import re
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError

SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.1)


@dataclass(frozen=True)
class Board:
    """A checkerboard of ``cols`` x ``rows`` inner corners, ``square_mm`` apart."""

    cols: int
    rows: int
    square_mm: float

    @classmethod
    def parse(cls, text: str, square_mm: float) -> Board:
        """``"9x6"`` -> Board(9, 6, square_mm); raises FieldappError on anything else."""
        match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
        if not match:
            raise FieldappError(f"--board {text!r}: expected COLSxROWS inner corners, e.g. 9x6")
        board = cls(int(match[1]), int(match[2]), square_mm)
        if board.cols < 3 or board.rows < 3:
            raise FieldappError(f"--board {text!r}: at least 3 x 3 inner corners are needed")
        if not square_mm > 0:
            raise FieldappError(f"--square-mm {square_mm}: must be positive")
        return board

    @property
    def pattern(self) -> tuple[int, int]:
        return self.cols, self.rows

    @property
    def is_symmetric(self) -> bool:
        """True when a half turn of the board looks the same (cols + rows even), so the
        detected corner order cannot be told from its reverse. 9 x 6 is asymmetric."""
        return (self.cols + self.rows) % 2 == 0

    def object_points_m(self) -> NDArray[np.float64]:
        """(cols*rows, 3) corner positions on the board plane (z = 0), metres, OpenCV order."""
        grid = np.mgrid[0 : self.cols, 0 : self.rows].T.reshape(-1, 2)
        points = np.zeros((len(grid), 3))
        points[:, :2] = grid * self.square_mm / 1000.0
        return points


def to_gray8(image: NDArray[np.generic]) -> NDArray[np.uint8]:
    """A detection image: 8-bit grey. 16-bit IR is stretched to its 1st-99th percentile."""
    gray: NDArray[np.generic] = image
    if image.ndim == 3:
        gray = np.asarray(cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY))
    if gray.dtype == np.uint8:
        return np.ascontiguousarray(gray, dtype=np.uint8)
    values = gray.astype(np.float32)
    low, high = np.percentile(values, [1.0, 99.0])
    scaled = np.clip((values - low) / max(float(high - low), 1e-6), 0.0, 1.0)
    stretched: NDArray[np.uint8] = (np.sqrt(scaled) * 255.0).astype(np.uint8)  # sqrt: IR contrast
    return stretched


def detect_corners(image: NDArray[np.generic], board: Board) -> NDArray[np.float32] | None:
    """Inner corners, (cols*rows, 2) float32 pixels refined to sub-pixel, or None if not found.

    OpenCV's classic detector with ``cornerSubPix`` (as accurate as the Harris corners of the
    paper), the sector-based detector as a fallback for harder images.
    """
    gray = to_gray8(image)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, board.pattern, flags)
    if not found:
        found, corners = cv2.findChessboardCornersSB(gray, board.pattern, cv2.CALIB_CB_ACCURACY)
        if not found:
            return None
    corners = corners.reshape(-1, 2).astype(np.float32)
    half = _subpix_half_window(corners, board)
    refined = cv2.cornerSubPix(
        gray, corners.reshape(-1, 1, 2), (half, half), (-1, -1), SUBPIX_CRITERIA
    )
    return np.asarray(refined, np.float32).reshape(-1, 2)


def _subpix_half_window(corners: NDArray[np.float32], board: Board) -> int:
    """Half the refinement window: OpenCV's usual 11 px, shrunk on small squares so that the
    window never reaches a neighbouring corner (which would pull the refinement off)."""
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(
        float(np.linalg.norm(np.diff(grid, axis=1), axis=2).min()),
        float(np.linalg.norm(np.diff(grid, axis=0), axis=2).min()),
    )
    return int(np.clip(round(spacing / 2), 2, 11))


def corner_zero_is_dark(
    image: NDArray[np.generic], corners: NDArray[np.float32], board: Board
) -> bool | None:
    """Whether the square diagonally outside corner 0 is dark; ``None`` when unclear.

    On an asymmetric board (cols + rows odd) the square outside the last corner has the other
    colour, so two views whose answers differ have their corner orders reversed.
    """
    gray = to_gray8(image).astype(np.float32)
    grid = corners.reshape(board.rows, board.cols, 2)
    along_col, along_row = grid[0, 1] - grid[0, 0], grid[1, 0] - grid[0, 0]
    outside = grid[0, 0] - 0.5 * (along_col + along_row)
    beside = grid[0, 0] + 0.5 * (along_col - along_row)  # the adjacent square: other colour
    samples = [_sample(gray, p) for p in (outside, beside)]
    if any(v is None for v in samples):
        return None
    a, b = samples
    assert a is not None and b is not None
    if abs(a - b) < 20.0:
        return None
    return a < b


def _sample(gray: NDArray[np.float32], point: NDArray[np.float32]) -> float | None:
    x, y = round(float(point[0])), round(float(point[1]))
    if not (1 <= x < gray.shape[1] - 1 and 1 <= y < gray.shape[0] - 1):
        return None
    return float(gray[y - 1 : y + 2, x - 1 : x + 2].mean())


def detect_all_corners(
    image: NDArray[np.generic], board: Board, max_boards: int = 6
) -> list[NDArray[np.float32]]:
    """Every visible board's corners: detect one, paint it over, look again."""
    work = to_gray8(image).copy()
    found = []
    for _ in range(max_boards):
        corners = detect_corners(work, board)
        if corners is None:
            break
        found.append(corners)
        grid = corners.reshape(board.rows, board.cols, 2)
        step = 1.5 * max(
            float(np.linalg.norm(grid[0, 1] - grid[0, 0])),
            float(np.linalg.norm(grid[1, 0] - grid[0, 0])),
        )
        centre = corners.mean(axis=0)
        hull = cv2.convexHull(corners.reshape(-1, 1, 2))
        outward = hull.reshape(-1, 2) - centre
        grown = (
            hull.reshape(-1, 2)
            + outward / (np.linalg.norm(outward, axis=1, keepdims=True) + 1e-9) * step
        )
        cv2.fillConvexPoly(work, grown.astype(np.int32), int(np.median(work)))
    return found
