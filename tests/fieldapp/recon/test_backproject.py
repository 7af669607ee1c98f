import cv2
import numpy as np
import pytest

from devices.camera.frames import KINECT_V2_PAPER, Intrinsics
from fieldapp.recon.backproject import backproject, backproject_pixels, ray_table


def test_flat_wall_backprojects_to_its_depth_and_pixels() -> None:
    rays = ray_table(KINECT_V2_PAPER)
    depth = np.full((424, 512), 1.5, np.float32)
    color = np.zeros((424, 512, 3), np.uint8)
    color[100, 200] = (10, 200, 30)
    cloud = backproject(depth, color, rays, crop_radius_m=10.0)
    assert len(cloud) == 424 * 512
    np.testing.assert_allclose(cloud.points[:, 2], 1.5)
    index = 100 * 512 + 200
    expected_x = (200 - KINECT_V2_PAPER.cx) / KINECT_V2_PAPER.fx * 1.5
    expected_y = (100 - KINECT_V2_PAPER.cy) / KINECT_V2_PAPER.fy * 1.5
    np.testing.assert_allclose(cloud.points[index], [expected_x, expected_y, 1.5], atol=1e-9)
    assert tuple(cloud.colors[index]) == (10, 200, 30)


def test_missing_depth_and_crop_radius_drop_points() -> None:
    rays = ray_table(KINECT_V2_PAPER)
    depth = np.full((424, 512), 2.0, np.float32)
    depth[:10] = np.nan
    depth[10:20] = 0.0
    cloud = backproject(depth, np.zeros((424, 512, 3), np.uint8), rays, crop_radius_m=2.1)
    ranges = np.linalg.norm(cloud.points, axis=1)
    assert ranges.max() <= 2.1
    assert 0 < len(cloud) < (424 - 20) * 512
    # every kept pixel is within the radius and every dropped valid one beyond it
    all_rays = rays[20:].reshape(-1, 3) * 2.0
    assert len(cloud) == int(np.sum(np.linalg.norm(all_rays, axis=1) <= 2.1))


def test_distorted_rays_reproject_to_their_pixels() -> None:
    intrinsics = Intrinsics(512, 424, 366.95, 364.79, 242.99, 207.70, (0.0966, -0.283, 0, 0, 0.105))
    rays = ray_table(intrinsics)
    v, u = 410, 505
    projected, _ = cv2.projectPoints(
        rays[v, u][None], np.zeros(3), np.zeros(3), intrinsics.K, np.array(intrinsics.distortion)
    )
    np.testing.assert_allclose(projected.ravel(), [u, v], atol=0.05)
    undistorted_guess = ((u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy)
    assert np.hypot(*(rays[v, u, :2] - undistorted_guess)) > 1e-3  # distortion made a difference


def test_mismatched_images_are_refused() -> None:
    rays = ray_table(KINECT_V2_PAPER)
    with pytest.raises(ValueError, match="do not match"):
        backproject(np.ones((10, 10), np.float32), np.zeros((10, 10, 3), np.uint8), rays, 2.0)


def test_picked_pixels_backproject_as_the_whole_frame_masked() -> None:
    """Back-projecting a frame's picked pixels gives the points of ``backproject`` with that
    mask, in the same order; the nearest depth is tested in metres as float64 (a depth of
    exactly float32(0.3) is beyond a 0.3 m minimum, as in ``backproject``)."""
    rng = np.random.default_rng(4)
    rays = ray_table(KINECT_V2_PAPER)
    depth = rng.uniform(0.2, 2.5, (424, 512)).astype(np.float32)
    depth[rng.random((424, 512)) < 0.1] = np.nan
    depth[5, 7] = np.float32(0.3)
    color = rng.integers(0, 256, (424, 512, 3), dtype=np.uint8)
    picked = rng.random((424, 512)) < 0.3
    picked[5, 7] = True
    whole = backproject(depth, color, rays, 2.0, 0.3, picked)
    index = np.flatnonzero(np.isfinite(depth) & picked)
    flat_depth, flat_color = depth.reshape(-1)[index], color.reshape(-1, 3)[index]
    some = backproject_pixels(index, flat_depth, flat_color, rays, 2.0, 0.3)
    np.testing.assert_array_equal(some.points, whole.points)
    np.testing.assert_array_equal(some.colors, whole.colors)
    assert np.float64(np.float32(0.3)) * rays[5, 7, 2] in some.points[:, 2]
    assert 0 < len(whole) < picked.sum()
