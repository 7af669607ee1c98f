"""A mission as the method runs it: drive to each station, turn the table through each view,
capture, write; as a generator of events that stops at step boundaries when asked.

:func:`run_mission` captures exactly the (station, view) pairs it is given (what the session
misses), in plan order: stations as planned, views turning up at one station and back down at
the next when the plan alternates. Each capture lands in the session (durably, listed only
when complete) with the pose the base reported on arrival and the angle the table reached.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Generator, Iterator
from dataclasses import asdict, dataclass, field

from devices.base.protocol import Pose
from devices.camera import Frame
from devices.table import GrblTable, TableException
from fieldapp.io.session import BasePose
from fieldapp.io.writer import SessionWriter
from fieldapp.mission.battery import BatteryWatch, check_before_start
from fieldapp.mission.control import Gate, MissionFault
from fieldapp.mission.estimate import RemainingTime
from fieldapp.mission.events import (
    Fault,
    MissionEvent,
    MissionProgress,
    MissionWarning,
    StationReached,
    ViewCaptured,
)
from fieldapp.mission.incidents import StationSkipped
from fieldapp.mission.plan import MissionPlan, StationPlan
from fieldapp.mission.steps import (
    Shot,
    capture_view,
    drive_to,
    prepare_base,
    prepare_table,
    turn_to,
)
from fieldapp.rig import Rig
from fieldapp.settings import BatterySettings

log = logging.getLogger(__name__)

THUMBNAIL_STRIDE = 8


@dataclass
class MissionContext:
    """What a mission runs with: the plan, the open rig, the session it writes, the controls,
    the battery levels to check."""

    plan: MissionPlan
    rig: Rig
    writer: SessionWriter
    gate: Gate
    battery: BatterySettings = field(default_factory=BatterySettings)


def visits(plan: MissionPlan, todo: list[tuple[int, int]]) -> list[tuple[StationPlan, list[int]]]:
    """The stations with views to capture, in plan order, each with its views in turning order."""
    wanted = set(todo)
    result = []
    for index, station in enumerate(plan.stations):
        views = [v for v in range(plan.views.count) if (station.number, v) in wanted]
        if plan.views.alternate and index % 2 == 1:
            views.reverse()
        if views:
            result.append((station, views))
    return result


def run_mission(context: MissionContext, todo: list[tuple[int, int]]) -> Iterator[MissionEvent]:
    """Capture ``todo``; yields every event. Raises :class:`MissionFault` or
    :class:`~fieldapp.mission.control.Aborted`."""
    plan, rig, gate = context.plan, context.rig, context.gate
    gate.checkpoint()  # a STOP before the start: the devices are not touched
    battery = BatteryWatch(rig.base, context.battery)
    for warning in (
        check_before_start(rig.base, context.battery),
        prepare_base(rig.base, gate),
        prepare_table(rig.table, gate),
    ):
        if warning is not None:
            yield warning
    stations = visits(plan, todo)
    total = len(plan.capture_keys())
    clock = ProgressClock(total, total - len(todo), moves=len(stations))
    yield clock.progress("starting")
    for station, views in stations:
        gate.checkpoint()
        clock.left.begin()  # after the checkpoint: a pause is not timed
        try:
            status, attempts = yield from drive_to(rig.base, station, plan, gate)
        except StationSkipped as skipped:
            clock.left.skipped(len(views))
            yield MissionWarning(f"{skipped}: its views are left for a resume", station.number)
            continue
        clock.left.moved()
        pose = status.pose
        log.info("station %d reached at %s", station.number, pose)
        yield StationReached(station.number, pose.x_m, pose.y_m, pose.yaw_deg, attempts)
        yield from _some(battery.check(station.number))
        for view in views:
            gate.checkpoint()
            clock.left.begin()
            yield (yield from capture_one(context, station.number, view, pose))
            clock.left.captured()
            yield clock.progress(f"station {station.number} view {view}", captured=True)
            yield from _some(battery.check(station.number, view))
    yield from _some(park_table(rig.table))


def park_table(table: GrblTable) -> MissionWarning | None:
    """After the last view: the table back to its machine zero, where a controller reset by
    the next opening of its port (DTR: a power-up, machine position 0 where the table stands)
    counts its angles from. A table left at 315 degrees would turn every view of the next
    mission 45 degrees off. Everything is captured by then: a failure is a warning."""
    try:
        table.park()
    except TableException as error:
        return MissionWarning(
            f"table: not turned back to its zero after the last view ({error}); turn it there "
            "before the controller is next reset, or its angles count from where it stands"
        )
    return None


def _some(warning: MissionWarning | None) -> Iterator[MissionWarning]:
    if warning is not None:
        yield warning


def capture_one(
    context: MissionContext, station: int, view: int, pose: Pose
) -> Generator[MissionWarning, None, ViewCaptured]:
    """Turn to ``view``, settle, capture within the quality limits and write the capture."""
    plan, rig, gate = context.plan, context.rig, context.gate
    angle_deg = yield from turn_to(rig.table, plan.views.angle_deg(view), plan, gate)
    gate.sleep(plan.settle_s)
    shot = yield from capture_view(rig.camera, plan, gate, (station, view))
    write_capture(context.writer, station, view, shot, angle_deg, pose)
    thumbnail = shot.frame.color[::THUMBNAIL_STRIDE, ::THUMBNAIL_STRIDE].copy()
    return ViewCaptured(station, view, angle_deg, shot.quality, shot.ok, thumbnail, shot.attempts)


def write_capture(
    writer: SessionWriter, station: int, view: int, shot: Shot, angle_deg: float, pose: Pose
) -> None:
    """Add the capture to the session (images first, then its listing)."""
    frame = shot.frame
    try:
        writer.add_capture(
            station,
            view,
            frame.depth_m,
            frame.color,
            ir=frame.ir,
            angle_deg=angle_deg,
            base_pose=BasePose(x=pose.x_m, y=pose.y_m, yaw_deg=pose.yaw_deg),
            frames=frames_combined(frame),
            quality={k: round(v, 6) for k, v in asdict(shot.quality).items()},
        )
    except OSError as error:
        where = error.filename or writer.session.folder
        raise MissionFault(
            Fault("session", f"cannot write {where}: {error.strerror}",
                  "free space on the drive or check it is writable; then resume the mission")
        ) from error  # fmt: skip


class ProgressClock:
    """Captures done of the plan's total, the time elapsed, and the time left from the
    measured time per move and per view (:class:`~fieldapp.mission.estimate.RemainingTime`,
    :attr:`left`) for this run's ``moves`` and views."""

    def __init__(
        self,
        total: int,
        already: int,
        moves: int = 0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.total = total
        self.already = already
        self.done = 0
        self._clock = clock
        self._start_s = clock()
        self.left = RemainingTime(moves, total - already, clock)

    def progress(self, step: str, captured: bool = False) -> MissionProgress:
        self.done += int(captured)
        elapsed_s = self._clock() - self._start_s
        return MissionProgress(
            self.already + self.done, self.total, elapsed_s, self.left.remaining_s, step
        )


def frames_combined(frame: Frame) -> int:
    """How many camera frames the capture combines."""
    combined = frame.meta.get("frames_combined", 1)
    return combined if isinstance(combined, int) else 1
