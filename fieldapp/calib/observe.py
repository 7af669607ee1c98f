"""A board seen in one capture: its 2D corners, their order parity and their 3D positions."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, pose_error
from fieldapp.calib.board import Board, corner_zero_is_dark, detect_all_corners, detect_corners
from fieldapp.calib.corners3d import Corners3D, lift_corners
from fieldapp.calib.rigid import fit_rigid_weighted
from fieldapp.io.session import Capture, CaptureImages, Session

MIN_LIFTED_FRACTION = 0.8
SYMMETRIC_MARGIN_DEG = 20.0
"""On a symmetric board the corner order chosen must fit the rig this much better than its
reverse (the two differ by a half turn, so a right choice wins by well over 100 degrees)."""

ItemT = TypeVar("ItemT")


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
    def centroid_m(self) -> NDArray[np.float64]:
        """Mean of the lifted corners (the board's centre)."""
        return np.asarray(np.nanmean(self.corners.points_m[self.corners.valid], axis=0))

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
    return _observation(session, capture, images, corners_px, board)


def observe_all(session: Session, capture: Capture, board: Board) -> list[Observation]:
    """Every board of this kind visible in the capture."""
    images = session.read_capture(capture)
    return [
        _observation(session, capture, images, corners_px, board)
        for corners_px in detect_all_corners(images.color, board)
    ]


def _observation(
    session: Session,
    capture: Capture,
    images: CaptureImages,
    corners_px: NDArray[np.float32],
    board: Board,
) -> Observation:
    intrinsics = session.calibration.depth_camera.intrinsics()
    return Observation(
        capture,
        corners_px,
        corner_zero_is_dark(images.color, corners_px, board),
        lift_corners(corners_px, images.depth_m, intrinsics, plane_radius_px(corners_px, board)),
    )


def plane_radius_px(corners_px: NDArray[np.float32], board: Board) -> int:
    """The local plane's half-size: 0.8 of a square (the board is flat that far around every
    inner corner), 4-15 px: more depth pixels, less noise, never off the board."""
    grid = corners_px.reshape(board.rows, board.cols, 2)
    spacing = min(
        float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2))),
        float(np.median(np.linalg.norm(np.diff(grid, axis=0), axis=2))),
    )
    return int(np.clip(round(0.8 * spacing), 4, 15))


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


def align_order(
    a: Observation, b: Observation, board: Board, T_a_b_prior: Matrix4 | None = None
) -> Observation | None:
    """``b`` with its corners in ``a``'s order, or None when the order cannot be told.

    A grid of points maps onto itself under a half turn, so the 3D fit alone cannot tell the
    order: on an asymmetric board the colour of the square outside corner 0 decides; failing
    that, the order whose transform lies closer to the prior (the calibration in force). A
    symmetric board (cols + rows even, e.g. 7 x 5) looks the same after a half turn, so the
    rig's geometry decides: see :func:`align_by_rig`.
    """
    if board.is_symmetric:
        return align_by_rig(a, b, T_a_b_prior)
    if a.corner_zero_dark is not None and b.corner_zero_dark is not None:
        return b if a.corner_zero_dark == b.corner_zero_dark else b.reversed()
    if T_a_b_prior is None:
        return None
    candidates = [b, b.reversed()]
    errors = [
        pose_error(fit_rigid_weighted(*paired_points(a, c)).T_target_source, T_a_b_prior)[1]
        for c in candidates
    ]
    return candidates[int(np.argmin(errors))]


def upright_tilt_deg(T_a_b: Matrix4) -> float:
    """How far ``T_a_b`` tilts the camera's vertical (its y axis): a turntable turning about a
    near-vertical axis, or a base driving on the ground, with an upright camera tilts it little."""
    return float(np.degrees(np.arccos(np.clip(T_a_b[1, 1], -1.0, 1.0))))


def align_by_rig(a: Observation, b: Observation, T_a_b_prior: Matrix4 | None) -> Observation | None:
    """``b`` in ``a``'s corner order on a symmetric board, or None when the rig cannot tell.

    The two orders give transforms a half turn about the board's normal apart. The right one
    is the one near the prior (the table's known step, the stations' nominal poses); without a
    prior, the one that keeps the upright camera's vertical (the table turns about a
    near-vertical axis). The winner must beat the other by ``SYMMETRIC_MARGIN_DEG``: a board
    lying flat seen without a prior stays ambiguous (a half turn about the vertical keeps it).
    """
    candidates = [b, b.reversed()]
    fits = [fit_rigid_weighted(*paired_points(a, c)).T_target_source for c in candidates]
    if T_a_b_prior is not None:
        errors = [pose_error(T, T_a_b_prior)[1] for T in fits]
    else:
        errors = [upright_tilt_deg(T) for T in fits]
    best = int(np.argmin(errors))
    if errors[1 - best] - errors[best] < SYMMETRIC_MARGIN_DEG:
        return None
    return candidates[best]


def match_by_prior(
    seen_a: Sequence[ItemT],
    seen_b: Sequence[ItemT],
    T_a_b_prior: Matrix4,
    radius_m: float,
    centre: Callable[[ItemT], NDArray[np.float64]],
) -> list[tuple[ItemT, ItemT]]:
    """Sightings of the same board from two frames: b's board centre moved by the prior lands
    within ``radius_m`` of a's (nearest wins)."""
    found = []
    for b in seen_b:
        moved = T_a_b_prior[:3, :3] @ centre(b) + T_a_b_prior[:3, 3]
        distances = [float(np.linalg.norm(centre(a) - moved)) for a in seen_a]
        if distances and min(distances) < radius_m:
            found.append((seen_a[int(np.argmin(distances))], b))
    return found
