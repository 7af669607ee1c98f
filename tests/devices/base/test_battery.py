"""The simulated base's battery lasts hours of operation, whatever the simulation's time scale:
it drains per metre driven and per second of simulated operation, never per loop iteration."""

from __future__ import annotations

import pytest

from devices.base.backend import NavProgress
from devices.base.motion import BatteryDrain, MotionModel
from devices.base.protocol import Goal, Pose
from devices.base.simulator import SimulatedMotionBackend


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def operate(time_scale: float, wall_s: float, tick_s: float, goals: list[Pose]) -> MotionModel:
    """Run the backend for ``wall_s`` seconds of its clock, polled every ``tick_s``, driving
    to each of ``goals`` in turn (the next once the last has arrived)."""
    clock = FakeClock()
    backend = SimulatedMotionBackend(MotionModel(seed=3), time_scale, clock)
    pending = list(goals)
    for tick in range(1, round(wall_s / tick_s) + 1):
        if pending and backend.model.progress is not NavProgress.MOVING:
            backend.begin_goal(Goal("g", pending.pop(0)))
        clock.now_s = tick * tick_s
        backend.update()
    return backend.model


@pytest.mark.parametrize("time_scale", [1.0, 1000.0])
@pytest.mark.parametrize("tick_s", [0.005, 0.05])
def test_standing_half_an_hour_costs_the_same_at_any_scale_and_poll_rate(
    time_scale: float, tick_s: float
) -> None:
    model = operate(time_scale, 1800.0, tick_s, [])
    assert model.battery_pct == pytest.approx(100.0 - BatteryDrain().pct_per_s * 1800.0)
    assert 93.0 < model.battery_pct < 95.0  # 12 %/h


@pytest.mark.parametrize("time_scale", [1.0, 1000.0])
def test_a_mission_of_nine_stations_costs_a_few_percent(time_scale: float) -> None:
    """The paper's serpentine over the 3 x 3 grid (12.8 m), then 15 minutes at the stations."""
    grid = [(0.0, 0.0), (1.6, 0.0), (3.2, 0.0), (3.2, 1.6), (1.6, 1.6), (0.0, 1.6)]
    grid += [(0.0, 3.2), (1.6, 3.2), (3.2, 3.2)]
    goals = [Pose(x, y, 0.0) for x, y in grid]
    model = operate(time_scale, 900.0, 0.01, goals)
    assert model.progress is NavProgress.ARRIVED
    assert 2.5 < 100.0 - model.battery_pct < 4.5, model.battery_pct


def test_a_full_battery_lasts_hours_standing_and_driving() -> None:
    drain = BatteryDrain()
    standing_h = 100.0 / drain.drained_pct(3600.0, 0.0)
    driving_h = 100.0 / drain.drained_pct(3600.0, 0.3 * 3600.0)  # at the top speed, 0.3 m/s
    assert 7.0 < standing_h < 10.0 and 1.0 < driving_h < 2.0
