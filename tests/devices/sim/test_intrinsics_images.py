"""Simulated IR checkerboard images calibrate back to the true intrinsics (OpenCV)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from devices.camera.frames import KINECT_V2_PAPER
from devices.sim.calibration_scenes import INTRINSICS_BOARD, intrinsics_images

pytestmark = pytest.mark.slow


def detect(ir: np.ndarray) -> np.ndarray | None:
    """Inner corners (N, 1, 2) float32 of the board in an IR image, or None."""
    gray = np.sqrt(ir.astype(np.float32) / max(int(ir.max()), 1)) * 255  # IR display stretch
    gray8 = np.clip(gray, 0, 255).astype(np.uint8)
    size = (INTRINSICS_BOARD.inner_cols, INTRINSICS_BOARD.inner_rows)
    found, corners = cv2.findChessboardCorners(gray8, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    return cv2.cornerSubPix(gray8, corners, (5, 5), (-1, -1), criteria)


def test_ir_board_images_calibrate_to_the_true_intrinsics() -> None:
    truth = KINECT_V2_PAPER
    object_points, image_points = [], []
    for _, ir in intrinsics_images(16, seed=2):
        assert ir.dtype == np.uint16 and ir.shape == (truth.height, truth.width)
        corners = detect(ir)
        if corners is not None:
            object_points.append(INTRINSICS_BOARD.object_points_m.astype(np.float32))
            image_points.append(corners)
    assert len(image_points) >= 12, "the board must be detectable in most IR images"
    rms, K, _, _, _ = cv2.calibrateCamera(
        object_points, image_points, (truth.width, truth.height), None, None
    )
    assert rms < 0.3
    for estimate, true in [
        (K[0, 0], truth.fx),
        (K[1, 1], truth.fy),
        (K[0, 2], truth.cx),
        (K[1, 2], truth.cy),
    ]:
        assert estimate == pytest.approx(true, rel=0.005)


def test_corners_are_where_the_pose_puts_them() -> None:
    """The detected corners match the projection of the true board pose to a fraction of a
    pixel: the images are geometrically exact, not just self-consistent."""
    ((T_camera_board, ir),) = intrinsics_images(1, seed=5)
    corners = detect(ir)
    assert corners is not None
    camera = INTRINSICS_BOARD.object_points_m @ T_camera_board[:3, :3].T + T_camera_board[:3, 3]
    projected, _ = cv2.projectPoints(camera, np.zeros(3), np.zeros(3), KINECT_V2_PAPER.K, None)
    error_px = np.linalg.norm(corners.reshape(-1, 2) - projected.reshape(-1, 2), axis=1)
    assert float(np.median(error_px)) < 0.15 and float(error_px.max()) < 0.5
