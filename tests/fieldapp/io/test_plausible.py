"""The plausibility bounds accept real depth cameras, not only the Kinect v2."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldapp.io.calibration import DepthCamera

REAL_CAMERAS = {
    # the seed paper's Kinect v2 (Zhang, IR images)
    "kinect2-paper": DepthCamera(width=512, height=424, fx=365.18, fy=364.49, cx=256.0, cy=209.59),
    # a Kinect v2's factory IR intrinsics (../shared/KINECT-V2.md)
    "kinect2-factory": DepthCamera(
        width=512,
        height=424,
        fx=366.95,
        fy=364.79,
        cx=242.99,
        cy=207.70,
        distortion=[0.0966, -0.283, 0.0, 0.0, 0.105],
    ),
    # RealSense D435 depth at 848 x 480 (87 x 58 degrees), 0.1 mm units
    "realsense-d435": DepthCamera(
        width=848, height=480, fx=421.5, fy=421.5, cx=422.1, cy=240.9, depth_scale=10000.0
    ),
    # Azure Kinect wide field of view, unbinned (120 x 120 degrees), rational model
    "azure-kinect-wfov": DepthCamera(
        width=1024,
        height=1024,
        fx=504.2,
        fy=504.3,
        cx=510.6,
        cy=512.0,
        distortion=[0.52, -0.03, 0.0001, -0.0002, -0.001, 0.86, 0.07, -0.006],
    ),
    # a 224 x 172 ToF module (pmd), ~62 x 45 degrees, strong barrel distortion
    "pmd-tof": DepthCamera(
        width=224,
        height=172,
        fx=210.0,
        fy=210.0,
        cx=111.0,
        cy=86.5,
        distortion=[-0.19, 0.08, 0.0, 0.0, -0.01],
    ),
}


@pytest.mark.parametrize("name", sorted(REAL_CAMERAS))
def test_real_depth_cameras_are_possible(name):
    from fieldapp.io.plausible import camera_problems

    assert camera_problems(Path("calibration.json"), REAL_CAMERAS[name]) == []


def test_every_impossible_field_is_named_at_once():
    from fieldapp.io.plausible import camera_problems

    camera = DepthCamera(
        width=512, height=424, fx=1e308, fy=364.0, cx=-5.0, cy=500.0, depth_scale=1e308
    )
    fields = [p.field for p in camera_problems(Path("c.json"), camera)]
    assert fields == [
        "depth_camera.fx",
        "depth_camera.cx",
        "depth_camera.cy",
        "depth_camera.depth_scale",
    ]
