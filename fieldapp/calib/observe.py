"""A board seen in one capture: its 2D corners, their order parity and their 3D positions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fieldapp.calib.board import Board, corner_zero_is_dark, detect_corners
from fieldapp.calib.corners3d import Corners3D, lift_corners
from fieldapp.io.session import Capture, Session

MIN_LIFTED_FRACTION = 0.8


@dataclass
class Observation:
    capture: Capture
    corners_px: NDArray[np.float32]
    corner_zero_dark: bool | None
    corners: Corners3D

    @property
    def name(self) -> str:
        target = getattr(self.capture, "target", None)
        suffix = f" ({target})" if target else ""
        return f"station {self.capture.station} view {self.capture.view}{suffix}"

    @property
    def lifted_fraction(self) -> float:
        return float(self.corners.valid.mean())

    def reversed(self) -> Observation:
        """The same observation with the corner order reversed (a half turn of the board)."""
        flip = None if self.corner_zero_dark is None else not self.corner_zero_dark
        corners = Corners3D(self.corners.points_m[::-1].copy(), self.corners.weights[::-1].copy())
        return Observation(self.capture, self.corners_px[::-1].copy(), flip, corners)


def observe(session: Session, capture: Capture, board: Board) -> Observation | None:
    """Detect ``board`` in the capture's colour image and lift its corners; None if not found."""
    images = session.read_capture(capture)
    corners_px = detect_corners(images.color, board)
    if corners_px is None:
        return None
    intrinsics = session.calibration.depth_camera.intrinsics()
    return Observation(
        capture,
        corners_px,
        corner_zero_is_dark(images.color, corners_px, board),
        lift_corners(corners_px, images.depth_m, intrinsics),
    )


def depth_problem(observation: Observation) -> str | None:
    """Why the observation's depth is unusable, or None."""
    if observation.lifted_fraction >= MIN_LIFTED_FRACTION:
        return None
    missing = int((~observation.corners.valid).sum())
    return (
        f"depth missing at {missing} of {len(observation.corners.valid)} corners in "
        f"{observation.name}: move the board closer (Kinect v2: 0.5-4.5 m), face it to the "
        "camera, and keep it out of direct sunlight"
    )


def paired_points(
    a: Observation, b: Observation
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Corners valid in both: (points of b, points of a, combined weights)."""
    both = a.corners.valid & b.corners.valid
    wa, wb = a.corners.weights[both], b.corners.weights[both]
    return b.corners.points_m[both], a.corners.points_m[both], wa * wb / (wa + wb)
