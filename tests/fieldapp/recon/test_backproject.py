import cv2
import numpy as np
import pytest

from devices.camera.frames import KINECT_V2_PAPER, Intrinsics
from fieldapp.recon.backproject import (
    backproject,
    backproject_pixels,
    overlap_radius,
    ray_table,
    rig_crop,
)
from fieldapp.recon.settings import CropSettings


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


def _calibration(height_m: float, spacing_m: float, ground: bool = True):  # type: ignore[no-untyped-def]
    """A 3 x 3 rig: every camera ``height_m`` above the ground, looking along +x pitched down
    45 degrees (OpenCV axes), stations ``spacing_m`` apart, station 5 the reference."""
    from devices.geometry import invert
    from fieldapp.io.calibration import Calibration

    forward = np.array([np.sqrt(0.5), 0.0, -np.sqrt(0.5)])
    right = np.array([0.0, -1.0, 0.0])

    def camera(x: float, y: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = np.column_stack([right, np.cross(forward, right), forward])
        T[:3, 3] = x, y, height_m
        return T

    field = {
        1 + i + 3 * j: camera(spacing_m * i, spacing_m * j) for i in range(3) for j in range(3)
    }
    to_reference = {s: (invert(field[5]) @ T).tolist() for s, T in field.items()}
    document = {
        "format": "fieldapp-calibration/1",
        "depth_camera": {"width": 512, "height": 424, "fx": 365.0, "fy": 365.0, "cx": 256.0,
                         "cy": 212.0},
        "stations": {"reference": 5, "to_reference": to_reference},
    }  # fmt: skip
    if ground:
        document["ground"] = {"matrix": field[5].tolist()}
    return Calibration.model_validate(document)


def test_the_crop_keeps_the_papers_reach_in_station_spacings_on_any_rig() -> None:
    """The paper's 2.25 m from cameras 1.3 m high keeps 1.84 m of ground around each, 1.15 of
    its 1.6 m station spacings; a rig 1.6 m high needs 2.44 m for the same (at 2.25 m its
    stations' clouds did not overlap: 8 of 9 left unregistered in a simulated plot)."""
    crop = CropSettings()
    assert rig_crop(crop, _calibration(1.3, 1.6)).radius_m == 2.25
    reach = np.sqrt(2.25**2 - 1.3**2) / 1.6
    assert rig_crop(crop, _calibration(1.6, 1.6)).radius_m == round(np.hypot(1.6, reach * 1.6), 2)
    assert rig_crop(crop, _calibration(1.6, 1.6)).radius_m == 2.44
    # 2.0 m apart: 1.15 spacings are 2.30 m of ground, seen from 1.3 m up
    assert rig_crop(crop, _calibration(1.3, 2.0)).radius_m == 2.64
    assert rig_crop(crop, _calibration(1.0, 1.6)).radius_m == 2.09


def test_stations_nearer_together_keep_the_papers_ground() -> None:
    """Stations nearer together than the paper's do not make the plot smaller: the outer
    plants stand as far beyond the outer stations, their leaves reach out as far. An
    independent renderer's stations 0.8 m apart had 1.68 m (0.92 m of ground), which cut the
    corner plants' outer leaves."""
    crop = CropSettings()
    assert rig_crop(crop, _calibration(1.3, 1.2)).radius_m == 2.25
    assert rig_crop(crop, _calibration(1.3, 0.8)).radius_m == 2.25
    assert rig_crop(crop, _calibration(1.41, 0.8)).radius_m == 2.32  # 1.84 m from 1.41 m up
    assert rig_crop(crop, _calibration(1.0, 1.2)).radius_m == 2.09  # lower: the same ground
    # registered within the paper's reach in spacings only, so that each station overlaps its
    # neighbours as on the paper's rig, not every station of the plot
    # 1.15 spacings of 0.8 m are 0.92 m of ground, seen from 1.41 m up
    assert overlap_radius(crop, _calibration(1.41, 0.8)) == 1.68
    assert overlap_radius(crop, _calibration(1.3, 1.6)) is None  # the paper's rig: the crop
    assert overlap_radius(crop, _calibration(1.6, 2.0)) is None  # farther apart: the crop
    assert overlap_radius(CropSettings(scale_to_rig=False), _calibration(1.3, 0.8)) is None


def test_the_crop_is_the_set_radius_when_the_rig_cannot_tell_or_scaling_is_off() -> None:
    assert rig_crop(CropSettings(), _calibration(1.6, 1.6, ground=False)).radius_m == 2.25
    off = CropSettings(scale_to_rig=False)
    assert rig_crop(off, _calibration(1.6, 1.6)).radius_m == 2.25
    mine = CropSettings(radius_m=3.0)  # a radius of one's own scales the same way
    reach = np.sqrt(3.0**2 - 1.3**2) / 1.6
    assert rig_crop(mine, _calibration(1.6, 1.6)).radius_m == round(np.hypot(1.6, reach * 1.6), 2)
