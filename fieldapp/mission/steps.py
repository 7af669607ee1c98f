"""The mission's three steps, each with its bounded retries: drive, turn, capture.

Each step is a generator: it yields a :class:`MissionWarning` for every retry and returns its
result. A failure that a retry cannot safely fix raises :class:`MissionFault` with what
happened and what to do. Retrying is safe when the device is at rest and the retry cannot do
harm: a goal the base gave up on, a base link that came back (the base stopped itself: its
watchdog), a table move that ended off target, a camera that timed out, a capture below quality.
An alarm, a disconnected table or camera, or a base stopped by someone else is left to the
operator. While a stop is under way every error ends the step with :class:`Aborted`.
"""

from __future__ import annotations

import logging
import time
import uuid
from collections.abc import Generator
from dataclasses import dataclass

from devices.base import (
    BaseClient,
    BaseError,
    BaseOffline,
    BaseRequestRejected,
    BaseStopped,
    LinkClosed,
    NavigationFailed,
)
from devices.base.protocol import BaseState, ErrorCode, Pose, Status
from devices.camera import CameraError, CameraTimeout, DepthCamera, Frame
from devices.camera.quality import QualityReport, QualityThresholds, assess
from devices.table import GrblTable, TableAlarm, TableException, TableMissedTarget
from fieldapp.mission.control import Aborted, Gate, MissionFault
from fieldapp.mission.events import Fault, MissionWarning
from fieldapp.mission.incidents import Choice, Incident, IncidentKind, StationSkipped, decide
from fieldapp.mission.plan import MissionPlan, StationPlan

log = logging.getLogger(__name__)

RESUME_ADVICE = "then resume the mission (`fieldapp mission resume SESSION`)"


def _fault(gate: Gate, device: str, what: str, advice: str) -> MissionFault | Aborted:
    if gate.stop_requested:
        return Aborted(f"stopped ({device}: {what})")
    return MissionFault(Fault(device, what, f"{advice}; {RESUME_ADVICE}"))


# --- base ---------------------------------------------------------------------------------


def drive_to(
    base: BaseClient, station: StationPlan, plan: MissionPlan, gate: Gate
) -> Generator[MissionWarning, None, tuple[Status, int]]:
    """Drive to ``station``; returns (the status on arrival, attempts). A lost link or a path
    still blocked after the retries is decided by the plan's ``incidents`` policy (may raise
    :class:`StationSkipped`)."""
    goal = Pose(station.x_m, station.y_m, station.yaw_deg)
    attempts = plan.retries.navigation + 1
    attempt = 0
    while True:
        attempt += 1
        goal_id = f"s{station.number:02d}-{uuid.uuid4().hex[:8]}"
        try:
            _goto(base, goal_id, goal)
            *_, status = base.follow_goal(goal_id, plan.navigation_timeout_s)
            return status, attempt
        except NavigationFailed as error:
            kind, problem = IncidentKind.BLOCKED_PATH, str(error)
            advice = "clear the path to the station or check the map"
        except BaseStopped as error:
            if "link lost" not in str(error):
                raise _fault(gate, "base", f"{error} (stopped by its operator?)",
                             "check the base and its emergency stop") from error  # fmt: skip
            kind, problem = IncidentKind.LOST_LINK, str(error)
            advice = "check the Wi-Fi link to the base"
        except BaseOffline as error:
            kind, problem = IncidentKind.LOST_LINK, f"link lost: {error}"
            advice = "the base stops itself within a second (watchdog); check the Wi-Fi link "
            advice += "and the base's bridge"
        except LinkClosed as error:  # the application closed the base's link (it is quitting)
            raise _fault(
                gate, "base", str(error), f"open the base's link again, {RESUME_ADVICE}"
            ) from error
        except BaseError as error:
            raise _fault(gate, "base", str(error), "check the plan's station poses against "
                         "the base's map") from error  # fmt: skip
        what = f"station {station.number}: {problem}"
        if gate.stop_requested:
            raise _fault(gate, "base", what, advice)
        if kind is IncidentKind.BLOCKED_PATH and attempt < attempts:
            yield MissionWarning(f"{what}; trying again", station.number)
        else:
            choice = _incident_choice(kind, station.number, what, plan, gate, attempt < attempts)
            if choice is Choice.STOP:
                raise _fault(gate, "base", what, advice)
            if choice is Choice.SKIP_STATION:  # the mission goes on: the base gets ready
                _ready_for_goal(base, gate)
                raise StationSkipped(station.number, problem)
            attempts = max(attempts, attempt + 1)
            yield MissionWarning(f"{what}; resuming ({choice.value})", station.number)
        gate.sleep(plan.retries.base_link_wait_s if kind is IncidentKind.LOST_LINK else 0.0)
        _ready_for_goal(base, gate)


def _goto(base: BaseClient, goal_id: str, goal: Pose) -> None:
    """Send the base to ``goal``. Refused ``busy`` because a goal this client sent earlier is
    moving (a station's request the link lost that reached the base after the station was
    given up, after :func:`_ready_for_goal` had found the base at rest), that goal is
    cancelled and ``goal`` sent again, once; a goal the client did not send is left alone
    and the refusal stands."""
    try:
        base.goto(goal_id, goal, wait=False)
        return
    except BaseRequestRejected as error:
        if error.code != ErrorCode.BUSY.value or not _cancel_own_goal(base, base.status()):
            raise
    base.goto(goal_id, goal, wait=False)


def _cancel_own_goal(base: BaseClient, status: Status) -> bool:
    """Cancel the goal ``status`` shows moving when this client sent it (a request of an
    earlier attempt that reached the base after all); False, and nothing cancelled, when the
    goal moving is another client's (an operator driving the base by hand)."""
    if status.state is not BaseState.MOVING or not status.goal_id:
        return True
    if not base.sent_goal(status.goal_id):
        return False
    log.warning("goal %s of an earlier attempt is moving the base: cancelled", status.goal_id)
    base.cancel(status.goal_id)
    return True


def _incident_choice(
    kind: IncidentKind, station: int, what: str, plan: MissionPlan, gate: Gate, retry_left: bool
) -> Choice:
    """The plan's policy for ``kind``; an automatic resume only while retries are left."""
    policy: str
    if kind is IncidentKind.LOST_LINK:
        policy = plan.incidents.lost_link
        if policy == "resume" and not retry_left:
            policy = "stop"
    else:
        policy = plan.incidents.blocked_path
    return decide(policy, Incident(kind, station, what), gate.operator_prompt)


def _ready_for_goal(base: BaseClient, gate: Gate) -> None:
    """Before another goal: after a lost link the base is latched (stopped by its watchdog),
    so the latch is cleared; a goal of an earlier attempt still moving (its request arrived
    after all) is cancelled, another client's is not (:func:`_cancel_own_goal`: the next goto
    is refused with the reason). A STOP that came meanwhile is never undone (see
    :func:`_reset_unless_stopped`)."""
    try:
        status = base.status()
    except BaseOffline:
        return  # the next goto says so
    if status.state is BaseState.MOVING:
        _cancel_own_goal(base, status)
    elif status.state is BaseState.STOPPED and status.error == "link lost":
        log.info("base latched after a lost link: resetting before the next goal")
        _reset_unless_stopped(base, gate)


def _reset_unless_stopped(base: BaseClient, gate: Gate) -> None:
    """Clear the base's stop latch, unless the operator stopped the mission: a STOP that came
    between the check and the reset is applied again, so the base stays latched."""
    gate.raise_if_stopped()
    base.reset()
    if gate.stop_requested:
        base.stop()
        gate.raise_if_stopped()


def prepare_base(base: BaseClient, gate: Gate) -> MissionWarning | None:
    """Before a mission: the base answers; a stop latch left set is cleared (with a warning)."""
    try:
        status = base.status()
        if status.state is not BaseState.STOPPED:
            return None
        _reset_unless_stopped(base, gate)
    except BaseOffline as error:
        advice = f"check the Wi-Fi link to the base and the base's bridge; {RESUME_ADVICE}"
        raise MissionFault(Fault("base", f"link lost: {error}", advice)) from error
    except BaseError as error:
        advice = f"check the base and its link; {RESUME_ADVICE}"
        raise MissionFault(Fault("base", str(error), advice)) from error
    return MissionWarning(f"the base's stop latch was set ({status.error}); cleared to start")


# --- table --------------------------------------------------------------------------------


def turn_to(
    table: GrblTable, angle_deg: float, plan: MissionPlan, gate: Gate
) -> Generator[MissionWarning, None, float]:
    """Turn the table to ``angle_deg``; returns the angle reached."""
    attempts = plan.retries.table + 1
    for attempt in range(1, attempts + 1):
        gate.raise_if_stopped()  # a hold sent before the move would not stop it
        try:
            return table.goto_deg(angle_deg)
        except TableMissedTarget as error:
            if gate.stop_requested or attempt == attempts:
                raise _fault(gate, "table", str(error), "check the table turns freely") from error
            yield MissionWarning(f"table: {error}; trying again")
        except TableAlarm as error:
            raise _fault(gate, "table", str(error), "check the table for an obstruction or a "
                         "stalled motor, then unlock or home it (`fieldapp table --port PORT "
                         "unlock` or `home`)") from error  # fmt: skip
        except TableException as error:
            raise _fault(gate, "table", str(error), "check the table's USB cable and the "
                         "controller's power") from error  # fmt: skip
    raise AssertionError("unreachable")  # pragma: no cover


def prepare_table(table: GrblTable, gate: Gate, timeout_s: float = 60.0) -> MissionWarning | None:
    """Before a mission: no alarm, a known position; a held move is carried to its end (not
    after a STOP: the table stays held)."""
    try:
        status = table.status()
        if status.state == "Alarm":
            raise TableAlarm(status.alarm_code, "controller locked in Alarm")
        if not table.position_known:
            raise MissionFault(Fault("table", f"position unknown ({status})",
                               "turn the table to its zero mark by hand and confirm it "
                               "(`fieldapp table --port PORT confirm`); with homing switches, "
                               "home it (`fieldapp table --port PORT home`)"))  # fmt: skip
        if status.state not in ("Hold", "Door"):
            return None
        gate.raise_if_stopped()
        table.resume()
        deadline_s = time.monotonic() + timeout_s
        while table.status().state != "Idle":
            if gate.stop_requested:
                table.hold()  # the STOP's hold may have come before the resume
                gate.raise_if_stopped()
            if time.monotonic() > deadline_s:
                raise MissionFault(Fault("table", "a held move did not finish", "check the table"))
            time.sleep(0.05)
    except TableException as error:
        advice = "unlock or home the table (`fieldapp table --port PORT unlock` or `home`)"
        raise MissionFault(Fault("table", str(error), f"{advice}; {RESUME_ADVICE}")) from error
    return MissionWarning(f"the table was held ({status}); its move was finished to start")


# --- camera -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Shot:
    """A capture and its quality (``ok``: within the plan's limits)."""

    frame: Frame
    quality: QualityReport
    ok: bool
    attempts: int


def capture_view(
    camera: DepthCamera, plan: MissionPlan, gate: Gate, where: tuple[int, int]
) -> Generator[MissionWarning, None, Shot]:
    """Capture one view (median of the plan's frames) within the quality limits."""
    limits = plan.quality.thresholds()
    timeouts = lows = 0
    best: Shot | None = None
    station, view = where
    while True:
        gate.raise_if_stopped()
        try:
            shot = _shoot(camera, plan, limits, timeouts + lows + 1)
        except CameraTimeout as error:
            timeouts += 1
            if gate.stop_requested or timeouts > plan.retries.camera:
                raise _fault(gate, "camera", f"s{station} v{view}: {error}", "check the "
                             "camera's USB 3 cable and power") from error  # fmt: skip
            yield MissionWarning(f"camera: {error}; trying again", station, view)
            continue
        except CameraError as error:
            advice = "check the camera's cable and power"
            raise _fault(gate, "camera", str(error), advice) from error
        if shot.ok:
            return shot
        problems = "; ".join(shot.quality.problems(limits))
        best = shot if best is None or shot.quality.fill_rate > best.quality.fill_rate else best
        lows += 1
        if lows > plan.retries.quality:
            if plan.keep_low_quality:
                yield MissionWarning(f"kept below quality: {problems}", station, view)
                return best
            raise _fault(gate, "camera", f"s{station} v{view} below quality: {problems}",
                         "clean the lens, shade the plot from direct sun, or relax the plan's "
                         "quality limits")  # fmt: skip
        yield MissionWarning(f"capture below quality ({problems}); trying again", station, view)


def _shoot(camera: DepthCamera, plan: MissionPlan, limits: QualityThresholds, attempt: int) -> Shot:
    """One capture; its age counts from when it was asked for (an older frame is stale)."""
    asked_s = time.monotonic()
    frame = camera.capture(plan.frames_per_capture, plan.frame_timeout_s)
    quality = assess(frame, camera.intrinsics, limits, now_s=asked_s)
    return Shot(frame, quality, quality.ok(limits), attempt)
