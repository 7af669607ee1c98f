"""The mission runner: one thread running :func:`~fieldapp.mission.execute.run_mission`, with
the operator's controls and a psygnal signal for every event.

States: ``idle`` -> ``running`` (<-> ``paused`` at a step boundary) -> ``stopping`` (after
:meth:`MissionRunner.abort` or :meth:`MissionRunner.stop`) -> ``finished`` (complete, aborted or
stopped) or ``failed`` (a fault). :meth:`~MissionRunner.abort` ends the mission at the next step
boundary; :meth:`~MissionRunner.stop` also holds the table and stops the base at once (the base's
stop latch is set; the next mission clears it). Signals fire on the runner's thread.
"""

from __future__ import annotations

import logging
import threading

from psygnal import Signal

from fieldapp.io.writer import SessionWriter
from fieldapp.mission.control import Aborted, Gate, MissionFault
from fieldapp.mission.events import (
    Fault,
    MissionEvent,
    MissionProgress,
    MissionResult,
    MissionState,
    MissionWarning,
    Outcome,
    StationReached,
    ViewCaptured,
)
from fieldapp.mission.execute import MissionContext, run_mission
from fieldapp.mission.folder import missing_keys, write_status
from fieldapp.mission.plan import MissionPlan
from fieldapp.rig import Rig

log = logging.getLogger(__name__)


class MissionRunner:
    """Runs ``plan`` on ``rig`` into ``writer``'s session, capturing only what it misses."""

    state_changed = Signal(object)
    """(MissionState)"""
    station_reached = Signal(object)
    """(StationReached)"""
    view_captured = Signal(object)
    """(ViewCaptured): its quality and a small thumbnail."""
    warning = Signal(object)
    """(MissionWarning): a retry, or something the operator should know."""
    progress = Signal(object)
    """(MissionProgress): captures done of the plan's total, time remaining."""
    finished = Signal(object)
    """(MissionResult): how it ended, what is missing, what to do."""

    def __init__(self, plan: MissionPlan, rig: Rig, writer: SessionWriter) -> None:
        self.plan = plan
        self.rig = rig
        self.writer = writer
        self.gate = Gate(self._on_pause)
        self._state = MissionState.IDLE
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stopper: threading.Thread | None = None
        self._done = threading.Event()
        self.result: MissionResult | None = None

    @property
    def state(self) -> MissionState:
        with self._lock:
            return self._state

    def missing(self) -> list[tuple[int, int]]:
        """What the session still misses of the plan."""
        return missing_keys(self.plan, self.writer)

    # --- controls ---------------------------------------------------------------------------

    def start(self) -> MissionRunner:
        if self._thread is not None:
            raise RuntimeError("a mission runner runs once; make a new one to resume")
        self._set_state(MissionState.RUNNING)
        self._thread = threading.Thread(target=self._run, name="mission", daemon=True)
        self._thread.start()
        return self

    def pause(self) -> None:
        """Pause at the next step boundary (state ``paused`` once there)."""
        self.gate.pause()

    def resume(self) -> None:
        self.gate.resume()

    def abort(self) -> None:
        """End the mission at the next step boundary (the current step finishes)."""
        self._begin_stopping()
        self.gate.abort()

    def stop(self) -> None:
        """End the mission now: hold the table and stop the base (on a helper thread, so this
        returns at once), then end at the interrupted step."""
        self._begin_stopping()
        self.gate.stop()
        with self._lock:
            if self._stopper is None:
                self._stopper = threading.Thread(
                    target=self._halt_devices, name="mission-stop", daemon=True
                )
                self._stopper.start()

    def wait(self, timeout_s: float | None = None) -> MissionResult | None:
        """The result once the mission has ended; ``None`` if it is still running."""
        self._done.wait(timeout_s)
        return self.result

    # --- the thread -------------------------------------------------------------------------

    def _run(self) -> None:
        todo = missing_keys(self.plan, self.writer)
        context = MissionContext(self.plan, self.rig, self.writer, self.gate)
        fault: Fault | None = None
        message = ""
        self._write_status(MissionState.RUNNING)
        try:
            for event in run_mission(context, todo):
                self._emit(event)
        except Aborted as reason:
            message = str(reason)
        except MissionFault as error:
            fault = error.fault
        except Exception as error:  # a bug must still end the mission cleanly
            log.exception("mission failed unexpectedly")
            fault = Fault("mission", f"unexpected error: {error!r}", "report it; resume")
        if self._stopper is not None:
            self._stopper.join(timeout=15.0)
        self._finish(fault, message)

    def _finish(self, fault: Fault | None, message: str) -> None:
        missing = missing_keys(self.plan, self.writer)
        captured = len(self.plan.capture_keys()) - len(missing)
        if not missing:
            outcome, fault, message = Outcome.COMPLETE, None, ""
        elif self.gate.stop_requested:
            outcome, fault = Outcome.STOPPED, None
        elif self.gate.abort_requested:
            outcome, fault = Outcome.ABORTED, None
        else:
            outcome = Outcome.FAILED
        self.result = MissionResult(outcome, captured, missing, fault, message)
        final = MissionState.FAILED if outcome is Outcome.FAILED else MissionState.FINISHED
        self._write_status(final, self.result)
        for line in self.result.lines():
            log.info("%s", line)
        self._set_state(final)
        self._done.set()
        self.finished.emit(self.result)

    def _emit(self, event: MissionEvent) -> None:
        if isinstance(event, ViewCaptured):
            self.view_captured.emit(event)
        elif isinstance(event, StationReached):
            self.station_reached.emit(event)
        elif isinstance(event, MissionWarning):
            log.warning("%s", event.text)
            self.warning.emit(event)
        elif isinstance(event, MissionProgress):
            self.progress.emit(event)

    def _halt_devices(self) -> None:
        """Hold the table and stop the base, each whatever happens to the other."""
        try:
            self.rig.table.hold()
        except Exception as error:  # the operator must hear of it, the base must still stop
            log.error("could not hold the table: %s", error)
            self.warning.emit(MissionWarning(f"could not hold the table: {error}"))
        try:
            self.rig.base.stop()
        except Exception as error:
            log.error("could not stop the base: %s", error)
            self.warning.emit(MissionWarning(f"could not stop the base: {error}"))

    def _write_status(self, state: MissionState, result: MissionResult | None = None) -> None:
        try:
            write_status(self.writer.session.folder, state.value, result)
        except OSError as error:
            log.error("cannot record the mission's status: %s", error)

    def _begin_stopping(self) -> None:
        with self._lock:
            active = self._state in (MissionState.RUNNING, MissionState.PAUSED)
        if active:
            self._set_state(MissionState.STOPPING)

    def _on_pause(self, paused: bool) -> None:
        if self.state is not MissionState.STOPPING:
            self._set_state(MissionState.PAUSED if paused else MissionState.RUNNING)

    def _set_state(self, state: MissionState) -> None:
        with self._lock:
            if state is self._state:
                return
            self._state = state
        log.info("mission %s", state.value)
        self.state_changed.emit(state)
