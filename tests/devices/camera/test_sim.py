"""The simulated camera: the rig's current state, re-noising faithful to the simulator."""

from __future__ import annotations

import numpy as np
import pytest

from devices.camera.base import CameraDisconnected
from devices.camera.frames import Frame, Intrinsics
from devices.camera.sim import SimCamera
from devices.camera.sim_noise import cos_incidence
from devices.sim.render import ray_table
from devices.sim.world import SimWorld


def _rms_mm(depth_m: np.ndarray, truth_m: np.ndarray, mask: np.ndarray) -> float:
    both = mask & np.isfinite(depth_m)
    return float(1000 * np.sqrt(np.mean((depth_m[both] - truth_m[both]) ** 2)))


def test_renoised_frames_have_the_simulators_noise(
    flat_world: SimWorld, flat_truth: tuple[np.ndarray, np.ndarray]
) -> None:
    truth, near = flat_truth
    full = flat_world.render(np.random.default_rng(1))
    with SimCamera(flat_world, seed=2) as camera:
        fast = camera.read_frame()
    rms_full, rms_fast = _rms_mm(full.depth_m, truth, near), _rms_mm(fast.depth_m, truth, near)
    assert rms_fast == pytest.approx(rms_full, rel=0.15)
    missing_full, missing_fast = np.isnan(full.depth_m).mean(), np.isnan(fast.depth_m).mean()
    assert abs(missing_fast - missing_full) < 0.01
    assert np.abs(fast.color.astype(int) - full.color.astype(int)).mean() < 4
    assert fast.ir is not None and full.ir is not None
    assert np.median(fast.ir[near]) == pytest.approx(np.median(full.ir[near]), rel=0.05)


def test_incidence_from_depth_matches_a_tilted_plane() -> None:
    intrinsics = Intrinsics(64, 48, 40.0, 40.0, 32.0, 24.0)
    v, u = np.mgrid[0:48, 0:64].astype(np.float64)
    x, y = (u - 32.0) / 40.0, (v - 24.0) / 40.0
    normal = np.array([0.0, np.sin(np.radians(60)), -np.cos(np.radians(60))])  # plane n.p = -2
    depth = -2.0 / (normal[0] * x + normal[1] * y + normal[2])
    cos = cos_incidence(depth.astype(np.float32), intrinsics)
    rays = np.stack([x, y, np.ones_like(x)], axis=2)
    expected = np.abs(rays @ normal) / np.linalg.norm(rays, axis=2)
    assert np.allclose(cos[1:-1, 1:-1], expected[1:-1, 1:-1], atol=2e-3)
    assert np.all(cos[0] == 1.0)  # undefined on the border


def test_frames_follow_the_rig_and_render_once_per_pose(flat_world: SimWorld) -> None:
    flat_world.set_table_angle_deg(0.0)
    with SimCamera(flat_world) as camera:
        first = [camera.read_frame() for _ in range(3)]
        assert camera.renders == 1
        assert [f.meta["frame_number"] for f in first] == [0, 1, 2]
        flat_world.set_table_angle_deg(180.0)
        turned = camera.read_frame()
        assert camera.renders == 2
        T = np.array(turned.meta["T_field_camera"])
        assert np.allclose(T, flat_world.T_field_camera())
        assert turned.meta["table_angle_deg"] == 180.0
    flat_world.set_table_angle_deg(0.0)
    # the sphere (top 0.4 m above the ground) is in front at 0 degrees and behind at 180:
    # the camera sees a point of it within 0.25 m of its centre's x only at 0 degrees
    assert _sees_sphere(first[0], camera) and not _sees_sphere(turned, camera)
    assert first[0].timestamp_s < first[1].timestamp_s < turned.timestamp_s


def _sees_sphere(frame: Frame, camera: SimCamera) -> bool:
    sphere = camera.world.scene.spheres[0]
    T = np.array(frame.meta["T_field_camera"])
    rays = ray_table(camera.intrinsics).reshape(-1, 3)
    depth = frame.depth_m.reshape(-1)
    valid = np.isfinite(depth)
    points = (rays[valid] * depth[valid, None]) @ T[:3, :3].T + T[:3, 3]
    on_sphere = (points[:, 2] > 0.05) & (np.abs(points[:, 0] - sphere.x_m) < 0.25)
    return bool(on_sphere.sum() > 500)


def test_fresh_renders_mode_renders_every_frame(flat_world: SimWorld) -> None:
    with SimCamera(flat_world, fresh_renders=True) as camera:
        a, b = camera.read_frame(), camera.read_frame()
        assert camera.renders == 2
    diff = a.depth_m - b.depth_m
    assert np.nanstd(diff) > 0.0005  # independent noise


def test_reading_a_closed_camera_is_a_typed_error(flat_world: SimWorld) -> None:
    camera = SimCamera(flat_world)
    with pytest.raises(CameraDisconnected, match="not open"):
        camera.read_frame()
    with pytest.raises(ValueError, match="fps"):
        SimCamera(flat_world, fps=0)


def test_closing_while_a_new_pose_renders_is_a_disconnect_not_a_crash():
    camera = SimCamera(SimWorld.default(seed=0), realtime=False)
    camera.open()
    camera._clean_renderer = None  # what close() does while the grabber is mid-read
    with pytest.raises(CameraDisconnected, match="closed"):
        camera._renoised((camera.world.base_pose(), 12.0))
    camera.close()
