"""Getting a mission ready: the rig opened from the plan's devices, the session folder started
(or reopened to resume), the calibration in force chosen; then a runner for it."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from fieldapp.io.session import SESSION_FILE
from fieldapp.io.writer import SessionWriter
from fieldapp.mission.calibration import calibration_in_force
from fieldapp.mission.folder import missing_keys, read_plan, reopen_session, start_session
from fieldapp.mission.plan import MissionPlan
from fieldapp.mission.runner import MissionRunner
from fieldapp.rig import Rig, open_rig
from fieldapp.settings import BatterySettings

if TYPE_CHECKING:
    from devices.sim.world import SimWorld

log = logging.getLogger(__name__)


@dataclass
class MissionSetup:
    """A plan, its open rig and its session. Close it (or use ``with``) to close the rig."""

    plan: MissionPlan
    rig: Rig
    writer: SessionWriter

    @property
    def folder(self) -> Path:
        return self.writer.session.folder

    def missing(self) -> list[tuple[int, int]]:
        return missing_keys(self.plan, self.writer)

    def runner(self, battery: BatterySettings | None = None) -> MissionRunner:
        """A runner for what the session misses; ``battery``: the levels it checks."""
        return MissionRunner(self.plan, self.rig, self.writer, battery)

    def close(self) -> None:
        self.rig.close()

    def __enter__(self) -> MissionSetup:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def new_mission(
    plan: MissionPlan, folder: Path, realtime: bool | None = None, world: SimWorld | None = None
) -> MissionSetup:
    """Open the rig and start a new session in ``folder`` with the plan and its calibration.

    ``world``: the simulated world to use (default: the plan's ``simulation`` seed and day)."""
    rig = _open(plan, realtime, world)
    try:
        calibration = calibration_in_force(plan, rig.world)
        writer = start_session(folder, plan, calibration)
    except BaseException:
        rig.close()
        raise
    return MissionSetup(plan, rig, writer)


def resume_mission(
    folder: Path, realtime: bool | None = None, world: SimWorld | None = None
) -> MissionSetup:
    """Reopen a mission folder (stopped, failed or crashed) and the rig its plan names."""
    plan = read_plan(folder)
    if (folder / SESSION_FILE).exists():
        SessionWriter.open(folder)  # a broken session is reported before the rig is opened
    rig = _open(plan, realtime, world)
    try:
        writer = reopen_session(folder, lambda: calibration_in_force(plan, rig.world))
    except BaseException:
        rig.close()
        raise
    log.info("%s: %d captures missing", folder, len(missing_keys(plan, writer)))
    return MissionSetup(plan, rig, writer)


def _open(plan: MissionPlan, realtime: bool | None, world: SimWorld | None) -> Rig:
    simulation = plan.simulation
    return open_rig(
        plan.devices, realtime=realtime, world=world, seed=simulation.seed, day=simulation.day
    )
