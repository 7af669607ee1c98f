"""The mission on the GUI: a :class:`~fieldapp.mission.MissionRunner` on the hub's open rig,
its psygnal signals (fired on the runner's thread) re-emitted as Qt signals, which Qt delivers
on the GUI thread.

The runner reads the camera through :class:`~ui.devices.stream_camera.StreamCamera`, so the
live preview keeps streaming during the mission. Starting a session (folder, plan, calibration)
and reopening one to resume run on a worker.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import TYPE_CHECKING

from PySide6 import QtCore

from fieldapp.mission.events import MissionResult, MissionState
from ui.devices.stream_camera import StreamCamera
from ui.workers import WorkerSet

if TYPE_CHECKING:
    from fieldapp.io.writer import SessionWriter
    from fieldapp.mission import MissionPlan, MissionRunner
    from fieldapp.rig import Rig
    from fieldapp.settings import BatterySettings
    from ui.devices.hub import DeviceHub

log = logging.getLogger(__name__)

ACTIVE = (MissionState.RUNNING, MissionState.PAUSED, MissionState.STOPPING)
LATE_THREAD_WAIT_S = 10.0
STOPPED_IN_SETUP = (
    "STOP was pressed while the mission was being set up; nothing was captured. "
    "Press Start again when ready"
)
DISCONNECTED_IN_SETUP = (
    "the devices were disconnected before the mission started; press Connect, then Start again"
)


def new_session(
    hub: DeviceHub, plan: MissionPlan, folder: Path
) -> tuple[MissionPlan, SessionWriter]:
    """Start ``folder`` as a new session of ``plan`` on the hub's rig (worker thread)."""
    from fieldapp.mission.calibration import calibration_in_force
    from fieldapp.mission.folder import start_session

    rig = _rig(hub)
    return plan, start_session(folder, plan, calibration_in_force(plan, rig.world))


def reopened_session(
    hub: DeviceHub, folder: Path, previous: MissionRunner | None = None
) -> tuple[MissionPlan, SessionWriter]:
    """The plan and session of an interrupted mission in ``folder`` (worker thread). A
    previous mission whose STOP ended it before its thread returned (a device call under way)
    is given ``LATE_THREAD_WAIT_S`` to return first, so two writers never list the same
    session at once."""
    from fieldapp.mission.calibration import calibration_in_force
    from fieldapp.mission.folder import read_plan, reopen_session

    if previous is not None and not previous.join(LATE_THREAD_WAIT_S):
        log.warning("the previous mission's thread is still in a device call; resuming anyway")
    rig = _rig(hub)
    plan = read_plan(folder)
    return plan, reopen_session(folder, lambda: calibration_in_force(plan, rig.world))


def _rig(hub: DeviceHub) -> Rig:
    from fieldapp.errors import FieldappError

    if hub.rig is None or hub.stream is None:
        raise FieldappError("the devices are not connected: press Connect first")
    return hub.rig


class MissionController(QtCore.QObject):
    """Starts, resumes, pauses, aborts and stops missions on the hub's rig."""

    state_changed = QtCore.Signal(object)
    station_reached = QtCore.Signal(object)
    view_captured = QtCore.Signal(object)
    warning = QtCore.Signal(object)
    progress = QtCore.Signal(object)
    finished = QtCore.Signal(object)
    started = QtCore.Signal(object, object)
    """(plan, session folder) once a runner has started."""
    failed_to_start = QtCore.Signal(object)

    def __init__(self, hub: DeviceHub, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.hub = hub
        self.runner: MissionRunner | None = None
        self.folder: Path | None = None
        self.battery: BatterySettings | None = None
        """The battery levels missions check (the settings' ``battery``)."""
        self._workers = WorkerSet()
        self._stop_before_start = False
        from ui.mission.incident_prompt import IncidentPrompt

        self.prompt = IncidentPrompt(self._stop_requested)
        """Asks the operator what to do after a lost link or a blocked path (the plan's
        ``incidents`` policy ``ask``)."""

    def _stop_requested(self) -> bool:
        runner = self.runner
        return runner is None or runner.gate.stop_requested

    @property
    def state(self) -> MissionState:
        return MissionState.IDLE if self.runner is None else self.runner.state

    @property
    def busy(self) -> bool:
        """A mission is being set up or is running (pause included)."""
        return self._workers.busy or self.state in ACTIVE

    def start(self, plan: MissionPlan, folder: Path) -> None:
        """Start a new session of ``plan`` in ``folder``."""
        if not self.busy:
            self._stop_before_start = False
            self._workers.run(lambda: new_session(self.hub, plan, folder), self._run, self._fail)

    def resume_session(self, folder: Path) -> None:
        """Capture what an interrupted session in ``folder`` still misses."""
        if not self.busy:
            self._stop_before_start = False
            previous = self.runner
            self._workers.run(
                lambda: reopened_session(self.hub, folder, previous), self._run, self._fail
            )

    def pause(self) -> None:
        if self.runner is not None:
            self.runner.pause()

    def carry_on(self) -> None:
        if self.runner is not None:
            self.runner.resume()

    def abort(self) -> None:
        """End at the next step boundary."""
        if self.runner is not None and self.state in ACTIVE:
            self.runner.abort()

    def stop(self) -> None:
        """End now: the runner holds the table and stops the base (returns at once). During
        the set-up the mission is not started at all."""
        if self._workers.busy:
            self._stop_before_start = True
        if self.runner is not None and self.state in ACTIVE:
            self.runner.stop()

    def shutdown(self, timeout_s: float = 20.0) -> MissionResult | None:
        """Stop a running mission and wait for its end (the window is closing)."""
        self._workers.wait(timeout_s)
        runner = self.runner
        if runner is None:
            return None
        if runner.state in ACTIVE:
            runner.stop()
        result = runner.wait(timeout_s)
        QtCore.QCoreApplication.processEvents()
        return result

    def _run(self, prepared: tuple[MissionPlan, SessionWriter]) -> None:
        from fieldapp.errors import FieldappError

        plan, writer = prepared
        rig, stream = self.hub.rig, self.hub.stream
        if self._stop_before_start:
            self._fail(FieldappError(STOPPED_IN_SETUP))
            return
        if rig is None or stream is None:
            self._fail(FieldappError(DISCONNECTED_IN_SETUP))
            return
        try:
            self._start_runner(plan, writer, dataclasses.replace(rig, camera=StreamCamera(stream)))
        except Exception as error:  # the page must not stay busy: say why and stay usable
            log.exception("the mission could not start")
            self.runner = None
            self._fail(error)

    def _start_runner(self, plan: MissionPlan, writer: SessionWriter, mission_rig: Rig) -> None:
        from fieldapp.mission import MissionRunner

        runner = MissionRunner(plan, mission_rig, writer, self.battery)
        runner.gate.operator_prompt = self.prompt
        runner.state_changed.connect(self._on_state)
        runner.station_reached.connect(self._on_station)
        runner.view_captured.connect(self._on_view)
        runner.warning.connect(self._on_warning)
        runner.progress.connect(self._on_progress)
        runner.finished.connect(self._on_finished)
        self.runner = runner
        self.folder = writer.session.folder
        self.started.emit(plan, self.folder)
        runner.start()

    def _fail(self, error: BaseException) -> None:
        log.error("mission not started: %s", error)
        self.failed_to_start.emit(error)

    # psygnal callbacks on the runner's thread: Qt queues each signal to the GUI thread.

    def _on_state(self, state: MissionState) -> None:
        self.state_changed.emit(state)

    def _on_station(self, event: object) -> None:
        self.station_reached.emit(event)

    def _on_view(self, event: object) -> None:
        self.view_captured.emit(event)

    def _on_warning(self, event: object) -> None:
        self.warning.emit(event)

    def _on_progress(self, event: object) -> None:
        self.progress.emit(event)

    def _on_finished(self, result: object) -> None:
        self.finished.emit(result)
