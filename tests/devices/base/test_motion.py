"""The simulated base's motion model against exact kinematics."""

from __future__ import annotations

import math

import pytest

from devices.base.backend import NavProgress
from devices.base.motion import BatteryDrain, MotionFault, MotionLimits, MotionModel, wrap_deg
from devices.base.protocol import Pose


def _run(model: MotionModel, dt_s: float = 0.05, limit_s: float = 120.0) -> float:
    elapsed_s = 0.0
    while model.progress is NavProgress.MOVING and elapsed_s < limit_s:
        model.step(dt_s)
        elapsed_s += dt_s
    return elapsed_s


@pytest.mark.parametrize("seed", range(8))
def test_arrives_a_few_cm_and_one_to_two_degrees_off(seed: int) -> None:
    model = MotionModel(seed=seed)
    goal = Pose(2.0, -1.0, 120.0)
    model.set_goal(goal)
    _run(model)
    assert model.progress is NavProgress.ARRIVED
    error_m = math.hypot(model.pose.x_m - goal.x_m, model.pose.y_m - goal.y_m)
    error_deg = abs(wrap_deg(model.pose.yaw_deg - goal.yaw_deg))
    assert 0.01 - 1e-9 <= error_m <= 0.04 + 1e-9
    assert 1.0 - 1e-9 <= error_deg <= 2.0 + 1e-9


def test_same_seed_same_arrival() -> None:
    poses = []
    for _ in range(2):
        model = MotionModel(seed=3)
        model.set_goal(Pose(1.0, 1.0, 0.0))
        _run(model)
        poses.append(model.pose)
    assert poses[0] == poses[1]


def test_travel_time_follows_speed_and_turn_rate_limits() -> None:
    limits = MotionLimits(
        max_speed_m_s=0.5,
        max_turn_rate_deg_s=90.0,
        arrival_error_m=(0.0, 0.0),
        arrival_error_deg=(0.0, 0.0),
    )
    model = MotionModel(limits)
    model.set_goal(Pose(0.0, 2.0, 0.0))  # turn +90, drive 2 m, turn -90
    elapsed_s = _run(model, dt_s=0.01)
    assert elapsed_s == pytest.approx(1.0 + 4.0 + 1.0, abs=0.03)
    assert model.pose.x_m == pytest.approx(0.0, abs=1e-9)
    assert model.pose.y_m == pytest.approx(2.0, abs=1e-9)


def test_speed_never_exceeds_the_limit() -> None:
    model = MotionModel(seed=1)
    model.set_goal(Pose(3.0, 0.0, 0.0))
    previous = model.pose
    while model.progress is NavProgress.MOVING:
        model.step(0.1)
        step_m = math.hypot(model.pose.x_m - previous.x_m, model.pose.y_m - previous.y_m)
        assert step_m <= model.limits.max_speed_m_s * 0.1 + 1e-9
        assert (
            abs(wrap_deg(model.pose.yaw_deg - previous.yaw_deg))
            <= model.limits.max_turn_rate_deg_s * 0.1 + 1e-9
        )
        previous = model.pose


def test_battery_drains_with_distance_and_time() -> None:
    limits = MotionLimits(battery=BatteryDrain(pct_per_m=1.0, pct_per_s=0.0))
    model = MotionModel(limits, seed=0)
    model.set_goal(Pose(2.0, 0.0, 0.0))
    _run(model)
    travelled_m = math.hypot(model.pose.x_m, model.pose.y_m)
    assert model.battery_pct == pytest.approx(100.0 - travelled_m, abs=1e-6)
    idle = MotionModel(MotionLimits(battery=BatteryDrain(pct_per_s=0.5, pct_per_m=0.0)))
    idle.step(10.0)
    assert idle.battery_pct == pytest.approx(95.0)


def test_halt_freezes_the_pose() -> None:
    model = MotionModel()
    model.set_goal(Pose(3.0, 0.0, 0.0))
    model.step(2.0)
    model.halt()
    here = model.pose
    model.step(5.0)
    assert model.pose == here
    assert model.progress is NavProgress.IDLE


def test_blocked_path_stops_then_aborts_after_the_timeout() -> None:
    model = MotionModel(MotionLimits(blocked_timeout_s=3.0))
    model.set_goal(Pose(3.0, 0.0, 0.0))
    model.step(1.0)
    model.faults.add(MotionFault.BLOCKED_PATH)
    here = model.pose
    model.step(2.0)
    assert model.pose == here
    assert model.progress is NavProgress.MOVING
    model.step(1.5)
    assert model.progress is NavProgress.ABORTED
    assert model.error == "path blocked"


def test_navigation_failure_aborts_without_moving() -> None:
    model = MotionModel()
    model.faults.add(MotionFault.NAV_FAILURE)
    model.set_goal(Pose(1.0, 1.0, 0.0))
    model.step(1.0)
    assert model.progress is NavProgress.ABORTED
    assert model.pose == Pose(0.0, 0.0, 0.0)


@pytest.mark.parametrize(
    ("angle", "wrapped"), [(190.0, -170.0), (-180.0, 180.0), (540.0, 180.0), (10.0, 10.0)]
)
def test_wrap_deg(angle: float, wrapped: float) -> None:
    assert wrap_deg(angle) == pytest.approx(wrapped)
