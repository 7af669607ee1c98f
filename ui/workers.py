"""Work off the GUI thread: a :class:`Job` runs a function on Qt's thread pool, and what it
returns, raises or (a generator) yields comes back on the GUI thread. :class:`WorkerSet` keeps
an owner's jobs and can wait for them when the window closes.

Why not superqt's workers, which this module replaced: each superqt worker is a ``QRunnable``
whose signals live on a ``QObject`` of its own, created on the GUI thread. The pool thread holds
the worker until ``run()`` returns, so the last reference often went on the pool thread and the
signals ``QObject`` was destroyed there, while the GUI thread could be delivering its events
(30 of 20 000 workers in a stress run; the likely cause of a segfault inside
``processEvents`` that ended a CI run). Its queued events could be dropped with it, and about
a third of the workers were never freed at all, each keeping what its function was given (300
live-view frames of 6 MB leaked 250 MB).

Here the only ``QObject`` a job's thread touches is one relay, made once on the GUI thread and
kept with the application: a job's thread posts plain Python callables to it, so no object of
the GUI thread can be destroyed by a job's thread, and a job is plain Python, freed by
reference counting wherever its last reference goes."""

from __future__ import annotations

import inspect
import logging
import threading
from collections.abc import Callable, Generator
from functools import partial
from itertools import count
from typing import Any

import shiboken6
from PySide6 import QtCore

log = logging.getLogger(__name__)

Callback = Callable[[Any], None]


class _Relay(QtCore.QObject):
    """Calls, on the GUI thread, what other threads post."""

    posted = QtCore.Signal(object)

    def __init__(self, parent: QtCore.QObject) -> None:
        super().__init__(parent)
        self.posted.connect(self._call, QtCore.Qt.ConnectionType.QueuedConnection)

    @QtCore.Slot(object)
    def _call(self, call: Callable[[], None]) -> None:
        call()


_relay: _Relay | None = None


def _gui_relay() -> _Relay:
    """The relay, made on first use by the GUI thread and owned by the application (so it
    outlives every job, and a new application gets a new one)."""
    global _relay
    if threading.current_thread() is not threading.main_thread():
        raise RuntimeError("jobs are started from the GUI thread")
    if _relay is None or not shiboken6.isValid(_relay):
        app = QtCore.QCoreApplication.instance()
        if app is None:
            raise RuntimeError("jobs need a QApplication")
        _relay = _Relay(app)
    return _relay


class _Cancelled(Exception):
    pass


class Job:
    """``function()`` on Qt's global thread pool. On the GUI thread, in this order:
    ``on_progress(value)`` for each value a generator yields, then one of ``on_done(result)``
    (what the function returns, or the generator's return value), ``on_error(error)``
    (anything it raised; logged when there is no ``on_error``) or ``on_cancelled()``, then
    ``on_finished()``. :attr:`running` is already False when they run."""

    def __init__(
        self,
        function: Callable[[], Any],
        *,
        on_done: Callback | None = None,
        on_error: Callable[[BaseException], None] | None = None,
        on_progress: Callback | None = None,
        on_cancelled: Callable[[], None] | None = None,
        on_finished: Callable[[], None] | None = None,
    ) -> None:
        self._function = function
        self._on_done, self._on_error, self._on_progress = on_done, on_error, on_progress
        self._on_cancelled, self._on_finished = on_cancelled, on_finished
        self._cancel = threading.Event()
        self._relay: _Relay | None = None
        self.running = False

    def start(self) -> None:
        """Queue the job on the pool (from the GUI thread)."""
        if self.running:
            raise RuntimeError("this job is already running")
        self._relay = _gui_relay()
        self._cancel.clear()
        self.running = True
        QtCore.QThreadPool.globalInstance().start(self._work)

    def cancel(self) -> None:
        """Ask the job to stop: a generator stops before its next step (closed on the job's
        thread, so its ``finally`` blocks run there); a plain function runs to its end and its
        result is dropped. ``on_cancelled`` follows, unless it had already ended."""
        self._cancel.set()

    # --- on the pool's thread -----------------------------------------------------------------

    def _work(self) -> None:
        try:
            result = self._function()
            if inspect.isgenerator(result):
                result = self._drive(result)
            ending = partial(self._end, "done", result)
        except _Cancelled:
            ending = partial(self._end, "cancelled", None)
        except BaseException as error:
            ending = partial(self._end, "error", error)
        self._post(ending)

    def _drive(self, steps: Generator[Any, Any, Any]) -> Any:
        while True:
            if self._cancel.is_set():
                steps.close()
                raise _Cancelled
            try:
                value = next(steps)
            except StopIteration as stop:
                return stop.value
            if self._on_progress is not None:
                self._post(partial(self._on_progress, value))

    def _post(self, call: Callable[[], None]) -> None:
        assert self._relay is not None
        self._relay.posted.emit(call)

    # --- on the GUI thread --------------------------------------------------------------------

    def _end(self, how: str, value: Any) -> None:
        self.running = False
        if how == "done" and self._cancel.is_set():
            how = "cancelled"
        try:
            if how == "done":
                if self._on_done is not None:
                    self._on_done(value)
            elif how == "error":
                (self._on_error or _log_error)(value)
            elif self._on_cancelled is not None:
                self._on_cancelled()
        finally:
            if self._on_finished is not None:
                self._on_finished()


class WorkerSet:
    """The jobs one owner started; none is dropped while running."""

    def __init__(self) -> None:
        self._running: dict[int, Job] = {}
        self._tokens = count()

    def run(
        self,
        function: Callable[[], Any],
        on_done: Callable[[Any], None] | None = None,
        on_error: Callable[[BaseException], None] | None = None,
    ) -> Job:
        """Call ``function()`` on the pool; ``on_done(result)`` or ``on_error(error)`` then
        runs on the GUI thread, the job already counted as finished (:attr:`busy`)."""
        token = next(self._tokens)  # the callbacks name the job, never hold it

        def forget() -> None:
            self._running.pop(token, None)

        def done(result: Any) -> None:
            forget()  # the owner's callback sees itself idle: its buttons come back
            if on_done is not None:
                on_done(result)

        def failed(error: BaseException) -> None:
            forget()
            (on_error or _log_error)(error)

        job = Job(function, on_done=done, on_error=failed, on_finished=forget)
        self._running[token] = job
        job.start()
        return job

    @property
    def busy(self) -> bool:
        return bool(self._running)

    def wait(self, timeout_s: float = 10.0) -> bool:
        """Process events until every job has finished; False on timeout."""
        return process_events_until(lambda: not self._running, timeout_s)


def process_events_until(ended: Callable[[], bool], timeout_s: float) -> bool:
    """Process the GUI thread's events until ``ended()`` (a job's owner waiting for it, as a
    window closes); False when ``timeout_s`` passed first."""
    deadline = QtCore.QDeadlineTimer(int(timeout_s * 1000))
    while not ended() and not deadline.hasExpired():
        QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 20)
        QtCore.QThread.msleep(2)
    return ended()


def _log_error(error: BaseException) -> None:
    log.error("background task failed: %s", error, exc_info=error)
