"""Rig geometry (stations, table, camera) and the live shared world state."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from devices.geometry import invert, pose_error, rotation_angle_deg
from devices.sim.rig import Pose2D, RigGeometry, StopErrors
from devices.sim.scene import empty_scene
from devices.sim.world import SimWorld


def test_stations_form_a_3_by_3_grid_with_5_at_the_field_origin() -> None:
    rig = RigGeometry()
    field_xy = {}
    for station in range(1, 10):
        T = rig.T_field_base(rig.station_pose(station))
        field_xy[station] = T[:2, 3]
    assert field_xy[5] == pytest.approx([0.0, 0.0])
    assert field_xy[1] == pytest.approx([-1.6, -1.6])
    assert field_xy[3] == pytest.approx([1.6, -1.6])  # row by row
    assert field_xy[9] == pytest.approx([1.6, 1.6])
    assert rig.station_pose(5) == Pose2D(1.6, 1.6, 0.0)  # map frame: station 1 at the origin
    with pytest.raises(ValueError, match=r"1\.\.9"):
        rig.station_pose(10)


def test_camera_is_1_3_m_up_pitched_down_and_off_the_axis() -> None:
    rig = RigGeometry()
    T = rig.T_field_camera(rig.station_pose(5), 0.0)
    assert T[2, 3] == pytest.approx(1.30)
    forward = T[:3, 2]
    assert np.degrees(np.arcsin(-forward[2])) == pytest.approx(45.0)
    assert np.hypot(*T[:2, 3]) == pytest.approx(np.hypot(rig.arm_m, rig.side_m))
    assert T[:3, 1] @ [0, 0, 1] < 0  # image y points down-ish


def test_view_step_maps_each_view_into_the_previous() -> None:
    rig = RigGeometry()
    pose = Pose2D(0.3, 0.2, 10.0)
    step = rig.T_camera0_camera(rig.view_step_deg)
    assert rotation_angle_deg(step[:3, :3]) == pytest.approx(45.0)
    for k in range(8):
        T_k = rig.T_field_camera(pose, 45.0 * k)
        T_next = rig.T_field_camera(pose, 45.0 * (k + 1))
        np.testing.assert_allclose(invert(T_k) @ T_next, step, atol=1e-12)
    # eight steps make a full turn (paper, Eq. 9)
    np.testing.assert_allclose(np.linalg.matrix_power(step, 8), np.eye(4), atol=1e-12)


def test_base_settles_on_the_soil() -> None:
    scene = empty_scene(3)
    rig = RigGeometry()
    pose = rig.station_pose(1)
    level = rig.T_field_base(pose)
    settled = rig.T_field_base(pose, scene.soil)
    assert scene.soil is not None
    assert settled[2, 3] == pytest.approx(scene.soil.height_at(*level[:2, 3]), abs=0.01)
    assert 0.0 < rotation_angle_deg(settled[:3, :3]) < 3.0  # tilted to the local slope


def test_stop_errors_are_a_few_cm_and_degrees() -> None:
    errors = StopErrors()
    rng = np.random.default_rng(0)
    goal = Pose2D(1.6, 1.6, 0.0)
    offsets = []
    for _ in range(200):
        reported, true = errors.base_stop(goal, rng)
        offsets.append((np.hypot(true.x_m - 1.6, true.y_m - 1.6), abs(true.yaw_deg)))
        assert np.hypot(reported.x_m - 1.6, reported.y_m - 1.6) < 0.1
    distance, yaw = np.array(offsets).T
    assert 0.01 < np.median(distance) < 0.06 and distance.max() < 0.15
    assert 0.3 < np.median(yaw) < 2.0 and yaw.max() < 5.0
    table = [errors.table_stop(45.0, rng) - 45.0 for _ in range(200)]
    assert 0.01 < np.std(table) < 0.06 and np.abs(table).max() <= 0.1


@pytest.fixture(scope="module")
def world() -> SimWorld:
    return SimWorld.default(seed=0)


def test_world_renders_from_its_live_state(world: SimWorld) -> None:
    world.set_base_pose(0.0, 0.0, 0.0)
    world.set_table_angle_deg(90.0)
    assert world.base_pose() == Pose2D(0.0, 0.0, 0.0) and world.table_angle_deg() == 90.0
    expected = world.rig.T_field_camera(Pose2D(0.0, 0.0, 0.0), 90.0, world.scene.soil)
    frame = world.render(np.random.default_rng(0))
    np.testing.assert_allclose(frame.meta["T_field_camera"], expected)
    world.set_table_angle_deg(180.0)
    other = world.render(np.random.default_rng(0))
    assert pose_error(np.array(other.meta["T_field_camera"]), expected)[1] == pytest.approx(90.0)
    changed = np.isfinite(frame.depth_m) != np.isfinite(other.depth_m)
    assert changed.any() or not np.allclose(
        np.nan_to_num(frame.depth_m), np.nan_to_num(other.depth_m)
    )


def test_world_state_is_thread_safe(world: SimWorld) -> None:
    def turn() -> None:
        for k in range(200):
            world.set_table_angle_deg(float(k))
            world.set_base_pose(float(k), float(k), float(k))

    threads = [threading.Thread(target=turn) for _ in range(4)]
    for thread in threads:
        thread.start()
    for _ in range(50):
        pose = world.base_pose()
        assert pose.x_m == pose.y_m == pose.yaw_deg  # never half-updated
    for thread in threads:
        thread.join()
    assert world.table_angle_deg() == 199.0
