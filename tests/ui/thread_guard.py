"""Catches widgets touched from threads other than the GUI thread (house rule 4).

Qt does not check it: reading ``QSpinBox.value()`` from a worker thread usually works, and now
and then returns a torn value or crashes. While a GUI test runs, every Python thread and every
job on Qt's thread pool (:class:`ui.workers.Job`) runs under a profiler that records each call
of a method bound to a ``QWidget`` (or a graphics item) made off the GUI thread, with the
caller's file and line.
The ``no_widgets_off_gui_thread`` fixture fails the test that made any.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

from PySide6 import QtWidgets

from ui.workers import Job

WIDGET_TYPES = (QtWidgets.QWidget, QtWidgets.QGraphicsItem)


class ThreadGuard:
    """Records widget calls made off the GUI thread while installed."""

    def __init__(self) -> None:
        self.violations: list[str] = []
        self._gui_thread = threading.main_thread()

    def profile(self, frame: FrameType, event: str, arg: Any) -> None:
        if event != "c_call" or threading.current_thread() is self._gui_thread:
            return
        owner = getattr(arg, "__self__", None)
        if isinstance(owner, WIDGET_TYPES):
            where = f"{frame.f_code.co_filename}:{frame.f_lineno}"
            name = f"{type(owner).__name__}.{getattr(arg, '__name__', '?')}"
            self.violations.append(
                f"{name} from thread {threading.current_thread().name} at {where}"
            )

    @contextmanager
    def installed(self) -> Iterator[None]:
        original_work: Callable[..., Any] = Job._work
        guard = self

        def guarded_work(job: Job) -> None:
            sys.setprofile(guard.profile)
            try:
                original_work(job)
            finally:
                sys.setprofile(None)

        threading.setprofile(self.profile)
        Job._work = guarded_work  # type: ignore[method-assign]
        try:
            yield
        finally:
            Job._work = original_work  # type: ignore[method-assign]
            threading.setprofile(None)  # type: ignore[arg-type]
