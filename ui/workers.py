"""Work off the GUI thread: a function runs on a superqt worker, its result or error comes
back on the GUI thread. :class:`WorkerSet` keeps the running workers alive and can wait for
them when the window closes."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from PySide6 import QtCore
from superqt.utils import WorkerBase, create_worker

log = logging.getLogger(__name__)


class WorkerSet:
    """The workers one owner started; none is dropped while running."""

    def __init__(self) -> None:
        self._running: set[WorkerBase[Any]] = set()

    def run(
        self,
        function: Callable[[], Any],
        on_done: Callable[[Any], None] | None = None,
        on_error: Callable[[BaseException], None] | None = None,
    ) -> WorkerBase[Any]:
        """Call ``function()`` on a worker thread; ``on_done(result)`` or ``on_error(error)``
        then runs on the GUI thread, the worker already counted as finished (:attr:`busy`)."""
        worker: WorkerBase[Any] = create_worker(function, _ignore_errors=True)
        self._running.add(worker)

        def forget(*_: object) -> None:
            self._running.discard(worker)

        def done(result: Any) -> None:
            forget()  # the owner's callback sees itself idle: its buttons come back
            if on_done is not None:
                on_done(result)

        def failed(error: BaseException) -> None:
            forget()
            (on_error or _log_error)(error)

        worker.returned.connect(done)
        worker.errored.connect(failed)
        worker.finished.connect(forget)
        worker.start()
        return worker

    @property
    def busy(self) -> bool:
        return bool(self._running)

    def wait(self, timeout_s: float = 10.0) -> bool:
        """Process events until every worker has finished; False on timeout."""
        deadline = QtCore.QDeadlineTimer(int(timeout_s * 1000))
        while self._running and not deadline.hasExpired():
            QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 20)
            QtCore.QThread.msleep(5)
        return not self._running


def _log_error(error: BaseException) -> None:
    log.error("background task failed: %s", error, exc_info=error)
