"""The operator's controls over a running mission, checked at step boundaries.

:meth:`Gate.checkpoint` is called by the mission between steps: it blocks while paused and
raises :class:`Aborted` once an abort or a stop was asked for. A stop is also immediate (the
runner holds the table and stops the base); :meth:`Gate.sleep` returns early on a stop.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from fieldapp.errors import FieldappError
from fieldapp.mission.events import Fault
from fieldapp.mission.incidents import OperatorPrompt


class Aborted(Exception):
    """The operator aborted (or stopped) the mission; raised at a step boundary."""


class MissionFault(FieldappError):
    """A fault the retries could not overcome: the mission stops."""

    def __init__(self, fault: Fault) -> None:
        self.fault = fault
        super().__init__(str(fault))


class Gate:
    """Pause, abort and stop flags shared by the runner and the mission's thread.

    ``on_pause(True)`` is called from the mission's thread when it actually pauses at a
    checkpoint, ``on_pause(False)`` when it carries on.
    """

    def __init__(self, on_pause: Callable[[bool], None] = lambda paused: None) -> None:
        self._on_pause = on_pause
        self._condition = threading.Condition()
        self._paused = False
        self._aborted = False
        self._stopped = threading.Event()
        self.operator_prompt: OperatorPrompt | None = None
        """Asks the operator about a lost link or a blocked path (set by the GUI before the
        mission starts); ``None``: nobody to ask (the plan's ``ask`` policies mean stop)."""

    @property
    def abort_requested(self) -> bool:
        with self._condition:
            return self._aborted

    @property
    def stop_requested(self) -> bool:
        return self._stopped.is_set()

    def pause(self) -> None:
        with self._condition:
            self._paused = True

    def resume(self) -> None:
        with self._condition:
            self._paused = False
            self._condition.notify_all()

    def abort(self) -> None:
        """End the mission at the next step boundary."""
        with self._condition:
            self._aborted = True
            self._condition.notify_all()

    def stop(self) -> None:
        """End the mission now: like :meth:`abort`, and sleeps end at once."""
        self._stopped.set()
        self.abort()

    def checkpoint(self) -> None:
        """A step boundary: wait while paused; raise :class:`Aborted` when asked to end."""
        with self._condition:
            must_pause = self._paused and not self._aborted
        if must_pause:  # listeners are called without the lock: they may resume or abort
            self._on_pause(True)
            with self._condition:
                self._condition.wait_for(lambda: not self._paused or self._aborted)
            self._on_pause(False)
        if self.abort_requested:
            raise Aborted("the operator ended the mission")

    def raise_if_stopped(self) -> None:
        """Raise :class:`Aborted` once a stop was asked for (not on an abort: the current step
        finishes)."""
        if self.stop_requested:
            raise Aborted("the operator stopped the mission")

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` unless a stop comes first (then raise :class:`Aborted`)."""
        if self._stopped.wait(seconds):
            raise Aborted("the operator stopped the mission")
