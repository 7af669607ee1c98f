"""Mission fixtures: small plans on the simulated rig moving at once."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from devices.camera import CameraInfo, DepthCamera, Intrinsics
from devices.sim.world import SimWorld
from fieldapp.mission import MissionPlan, MissionSetup, new_mission
from fieldapp.mission.plan import RetryLimits, ViewPlan, grid_stations
from fieldapp.settings import DeviceSettings

HANG_S = 90.0
"""The longest a mission test waits for an end or an event before failing: a hang detector,
never a speed requirement (the suite passes on a saturated machine)."""


def small_plan(
    stations: tuple[int, ...] = (5, 4), views: int | ViewPlan = 2, **fields: Any
) -> MissionPlan:
    """Stations of the 3 x 3 grid in the given order, ``views`` views, one frame per capture,
    no settling, short retry waits, simulated devices moving at once."""
    grid = {s.number: s for s in grid_stations()}
    values: dict[str, Any] = {
        "stations": [grid[n] for n in stations],
        "reference_station": 5 if 5 in stations else stations[0],
        "views": views if isinstance(views, ViewPlan) else ViewPlan(count=views),
        "frames_per_capture": 1,
        "settle_s": 0.0,
        "retries": RetryLimits(base_link_wait_s=0.1),
        "devices": DeviceSettings(realtime_simulation=False),
    }
    values.update(fields)
    return MissionPlan(**values)


@pytest.fixture(scope="session")
def sim_world() -> SimWorld:
    """The default world, built once (about a second); each mission's rig sets its state."""
    return SimWorld.default()


@pytest.fixture
def open_mission(tmp_path: Path, sim_world: SimWorld) -> Iterator[Callable[..., MissionSetup]]:
    """``open_mission(plan, realtime=False)``: a new mission in ``tmp_path/S``; closed after."""
    setups: list[MissionSetup] = []

    def make(plan: MissionPlan, realtime: bool = False) -> MissionSetup:
        sim_world.set_base_pose(1.6, 1.6, 0.0)  # where a fresh world's rig stands: station 5
        setup = new_mission(plan, tmp_path / "S", realtime=realtime, world=sim_world)
        setups.append(setup)
        return setup

    yield make
    for setup in setups:
        setup.close()


class WrappedCamera(DepthCamera):
    """A camera that reads through ``inner`` (a simulated camera) and lets a test change what
    ``_read`` does: the fault-injecting cameras of these tests subclass it."""

    def __init__(self, inner: DepthCamera) -> None:
        super().__init__()
        self.inner = inner
        self._is_open = True

    @property
    def intrinsics(self) -> Intrinsics:
        return self.inner.intrinsics

    @property
    def info(self) -> CameraInfo:
        return self.inner.info

    def _open(self) -> None: ...

    def _close(self) -> None: ...
