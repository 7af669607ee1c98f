"""The mission runner: one thread running :func:`~fieldapp.mission.execute.run_mission`, with
the operator's controls and a psygnal signal for every event.

States: ``idle`` -> ``running`` (<-> ``paused`` at a step boundary) -> ``stopping`` (after
:meth:`MissionRunner.abort` or :meth:`MissionRunner.stop`) -> ``finished`` (complete, aborted or
stopped) or ``failed`` (a fault). :meth:`~MissionRunner.abort` ends the mission at the next step
boundary; :meth:`~MissionRunner.stop` also holds the table and stops the base at once (the base's
stop latch is set; the next mission clears it). Signals fire on the runner's thread.

STOP always lands: a helper thread halts the devices and then gives the mission's thread
``stop_budget_s`` (1.5 s, on the runner's clock) to end at its interrupted step. If it has not
(a device call that does not return), the helper ends the mission itself: state ``finished``,
outcome ``stopped``, ``mission-status.json`` written; the late thread only refreshes the status
file when it finally returns. Whatever kills the mission's thread ends the mission as ``failed``
with the reason, never leaves it ``running``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

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
from fieldapp.settings import BatterySettings

log = logging.getLogger(__name__)

STOP_BUDGET_S = 1.5
"""From STOP to a terminal state, at most (runner's clock)."""
STOP_POLL_S = 0.01


class MissionRunner:
    """Runs ``plan`` on ``rig`` into ``writer``'s session, capturing only what it misses.

    ``battery``: the levels checked before the mission and at every station; ``clock`` and
    ``stop_budget_s``: how long STOP may take to land (tests inject a clock)."""

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

    def __init__(
        self,
        plan: MissionPlan,
        rig: Rig,
        writer: SessionWriter,
        battery: BatterySettings | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        stop_budget_s: float = STOP_BUDGET_S,
    ) -> None:
        self.plan = plan
        self.rig = rig
        self.writer = writer
        self.battery = battery or BatterySettings()
        self.gate = Gate(self._on_pause)
        self._clock = clock
        self.stop_budget_s = stop_budget_s
        self._state = MissionState.IDLE
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stopper: threading.Thread | None = None
        self._halted = threading.Event()
        self._ended = threading.Event()
        self._done = threading.Event()
        self._stop_asked_s: float | None = None
        self.stop_latency_s: float | None = None
        """Runner-clock seconds from STOP to the terminal state (``None`` without a STOP)."""
        self.forced_end = False
        """True when STOP ended the mission before its thread returned (a blocked step)."""
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
        thread = threading.Thread(target=self._run, name="mission", daemon=True)
        with self._lock:
            self._thread = thread
        thread.start()
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
        """End now: hold the table and stop the base (on a helper thread, so this returns at
        once), then end at the interrupted step, or after ``stop_budget_s`` whatever the step."""
        self._begin_stopping()
        self.gate.stop()
        with self._lock:
            if self._stopper is not None:
                return
            self._stop_asked_s = self._clock()
            stopper = threading.Thread(target=self._stop_sequence, name="mission-stop", daemon=True)
            stopper.start()  # started before it is published: whoever sees it may join it
            self._stopper = stopper

    def wait(self, timeout_s: float | None = None) -> MissionResult | None:
        """The result once the mission has ended; ``None`` if it is still running."""
        self._done.wait(timeout_s)
        return self.result

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait for the mission's thread itself (after a forced end it may still be inside a
        device call); True once it has returned (or never started)."""
        with self._lock:
            thread = self._thread
        if thread is not None:
            thread.join(timeout_s)
        return thread is None or not thread.is_alive()

    # --- the mission's thread ---------------------------------------------------------------

    def _run(self) -> None:
        fault: Fault | None = None
        message = ""
        try:
            fault, message = self._mission()
        except BaseException as error:  # whatever kills the thread ends the mission, said why
            log.exception("the mission's thread died")
            fault = Fault("mission", f"the mission's thread died: {error!r}", "report it; resume")
        finally:
            self._ended.set()
            if self.gate.stop_requested:
                self._halted.wait(self._budget_left_s())
            self._finish(fault, message)

    def _mission(self) -> tuple[Fault | None, str]:
        todo = missing_keys(self.plan, self.writer)
        context = MissionContext(self.plan, self.rig, self.writer, self.gate, self.battery)
        self._write_status(MissionState.RUNNING)
        try:
            for event in run_mission(context, todo):
                self._emit(event)
        except Aborted as reason:
            return None, str(reason)
        except MissionFault as error:
            return error.fault, ""
        except Exception as error:  # a bug must still end the mission cleanly
            log.exception("mission failed unexpectedly")
            return Fault("mission", f"unexpected error: {error!r}", "report it; resume"), ""
        return None, ""

    def _finish(self, fault: Fault | None, message: str, forced: bool = False) -> None:
        """The terminal state, once: the status file, the state, the result, ``finished``.
        A second call (the late thread after a forced end) only refreshes the status file."""
        with self._lock:
            first = self.result is None
            if self.result is None:
                self.result = self._result(fault, message)
                self.forced_end = forced
            result: MissionResult = self.result
        if not first:
            self._write_status(self._final_state(result), self._result(None, result.message))
            return
        final = self._final_state(result)
        self._write_status(final, result)
        for line in result.lines():
            log.info("%s", line)
        if self._stop_asked_s is not None:
            self.stop_latency_s = self._clock() - self._stop_asked_s
            log.info("STOP landed in %.3f s%s", self.stop_latency_s, " (forced)" if forced else "")
        self._set_state(final)
        self._done.set()
        self.finished.emit(result)

    def _result(self, fault: Fault | None, message: str) -> MissionResult:
        try:
            missing = missing_keys(self.plan, self.writer)
        except Exception as error:  # the result must still be given
            log.error("cannot list what the session misses: %s", error)
            missing = self.plan.capture_keys()
        captured = len(self.plan.capture_keys()) - len(missing)
        if not missing:
            outcome, fault, message = Outcome.COMPLETE, None, ""
        elif self.gate.stop_requested and fault is None:
            outcome = Outcome.STOPPED
        elif self.gate.abort_requested and fault is None:
            outcome = Outcome.ABORTED
        else:
            outcome = Outcome.FAILED
        return MissionResult(outcome, captured, missing, fault, message)

    @staticmethod
    def _final_state(result: MissionResult) -> MissionState:
        return MissionState.FAILED if result.outcome is Outcome.FAILED else MissionState.FINISHED

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

    # --- STOP's helper thread ---------------------------------------------------------------

    def _stop_sequence(self) -> None:
        """Halt the devices, then end the mission if its thread has not within the budget."""
        try:
            self._halt_devices()
        finally:
            self._halted.set()
        with self._lock:
            thread = self._thread
        if thread is None:
            return  # stopped before it started: start() will end at the first checkpoint
        while not self._ended.wait(STOP_POLL_S):
            if self._budget_left_s() <= 0.0:
                log.error(
                    "the mission's thread did not end within %.1f s of STOP", self.stop_budget_s
                )
                self._finish(None, "STOP ended the mission while a device call was still "
                             "under way; that step is not recorded", forced=True)  # fmt: skip
                return

    def _budget_left_s(self) -> float:
        asked_s = self._stop_asked_s
        if asked_s is None:
            return self.stop_budget_s
        return max(0.0, self.stop_budget_s - (self._clock() - asked_s))

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

    # --- state ------------------------------------------------------------------------------

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
            if state is self._state or self._state in TERMINAL:
                return
            self._state = state
        log.info("mission %s", state.value)
        self.state_changed.emit(state)


TERMINAL = (MissionState.FINISHED, MissionState.FAILED)
