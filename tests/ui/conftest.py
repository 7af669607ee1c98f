"""Fixtures for the GUI tests: a window on simulated devices (moving instantly), and a check
that a test leaves no thread and no top-level widget behind."""

from __future__ import annotations

import gc
import re
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import shiboken6
from PySide6 import QtCore, QtWidgets

from fieldapp.settings import Settings

from .thread_guard import ThreadGuard

LEAK_GRACE_S = 5.0
HANG_S = 90.0
"""The longest a wait for a state may take before the test fails: a hang detector, never a
speed requirement (the suite passes on a saturated machine; a passing wait returns as soon as
its state holds)."""


def _python_threads() -> set[threading.Thread]:
    """Live Python threads, without the placeholders Python makes for Qt's pool threads."""
    return {
        t
        for t in threading.enumerate()
        if t.is_alive() and not isinstance(t, threading._DummyThread)
    }


def _flush_deletes() -> None:
    for _ in range(3):
        QtCore.QCoreApplication.sendPostedEvents(None, QtCore.QEvent.Type.DeferredDelete)
        QtCore.QCoreApplication.processEvents()
        gc.collect()  # pyqtgraph's menus are parentless, owned by Python objects in cycles


def _plot_menu(widget: QtWidgets.QWidget) -> bool:
    """A hidden menu under a parentless menu: pyqtgraph gives each plot one ("Plot Options"
    and its submenus), owned by the plot's Python object. pytest can keep such objects alive
    past the teardown (likely: a captured log record holding an exception whose traceback holds the
    widget), so these are not counted; every other top-level widget is."""
    root: QtCore.QObject = widget
    while root.parent() is not None:
        root = root.parent()
    menus = isinstance(widget, QtWidgets.QMenu) and isinstance(root, QtWidgets.QMenu)
    return menus and not widget.isVisible()


@pytest.fixture(autouse=True)
def no_widgets_off_gui_thread() -> Iterator[ThreadGuard]:
    """Fail the test when a widget was called from a thread other than the GUI thread."""
    guard = ThreadGuard()
    with guard.installed():
        yield guard
    unique = list(dict.fromkeys(guard.violations))
    assert not unique, "widgets touched off the GUI thread:\n" + "\n".join(unique[:20])


THREAD_WARNING = re.compile(r"thread", re.IGNORECASE)
"""Qt's warnings of an object used across threads: "QObject::startTimer: Timers cannot be
started from another thread", "QObject: Cannot create children for a parent that is in a
different thread", "QObject::killTimer: Timers cannot be stopped from another thread", ..."""


def thread_warnings(messages: list[str]) -> list[str]:
    return [message for message in messages if THREAD_WARNING.search(message)]


@pytest.fixture(autouse=True)
def no_qt_thread_warnings(request: pytest.FixtureRequest, qtlog: Any) -> Iterator[None]:
    """Fail the test when Qt warned of an object used across threads. Qt only warns, and
    carries on with an object whose thread is wrong; what follows can crash much later (the
    kind of fault that ended a CI run with a segfault inside ``processEvents``)."""
    yield
    if request.node.get_closest_marker("qt_thread_warning_expected"):
        return
    found = thread_warnings([record.message for record in qtlog.records])
    assert not found, "Qt warned of a cross-thread use:\n" + "\n".join(found[:20])


@pytest.fixture
def no_leaks(qapp: QtWidgets.QApplication) -> Iterator[None]:
    """Fail when the test leaves a thread running or a top-level widget alive."""
    threads_before = _python_threads()
    widgets_before = set(qapp.topLevelWidgets())
    yield
    pool = QtCore.QThreadPool.globalInstance()
    assert pool.waitForDone(int(LEAK_GRACE_S * 1000)), "a worker is still running"
    deadline = time.monotonic() + LEAK_GRACE_S
    while _python_threads() - threads_before and time.monotonic() < deadline:
        time.sleep(0.05)
    leaked = sorted(t.name for t in _python_threads() - threads_before)
    assert not leaked, f"threads left running: {leaked}"
    _flush_deletes()
    extra = [w for w in qapp.topLevelWidgets() if w not in widgets_before and not _plot_menu(w)]
    assert not extra, f"top-level widgets left: {[type(w).__name__ for w in extra]}"


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """Default settings (every device simulated), instant simulators, files under tmp."""
    settings = Settings()
    settings.paths.sessions_dir = tmp_path / "sessions"
    settings.devices.realtime_simulation = False
    return settings


def _wait_until(condition: Callable[[], bool], timeout_s: float = HANG_S) -> bool:
    """Process Qt events until ``condition()`` holds; False after ``HANG_S`` (a shorter
    ``timeout_s`` is raised to it: a slow machine is not a failure)."""
    return _process_events(condition, max(timeout_s, HANG_S))


def _never_within(condition: Callable[[], bool], seconds: float) -> bool:
    """Process Qt events for ``seconds``; True when ``condition()`` never held (checks that
    something does NOT happen: a slow machine can only make it pass more easily)."""
    return not _process_events(condition, seconds)


def _process_events(condition: Callable[[], bool], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 20)
        if condition():
            return True
        time.sleep(0.005)
    return condition()


WaitUntil = Callable[..., bool]


@pytest.fixture
def wait_until() -> WaitUntil:
    """``wait_until(condition)``: process events until the condition holds (hang limit
    ``HANG_S``)."""
    return _wait_until


@pytest.fixture
def never_within() -> WaitUntil:
    """``never_within(condition, seconds)``: process events for ``seconds``; True when the
    condition never held."""
    return _never_within


@pytest.fixture
def make_window(
    no_leaks: None, settings: Settings, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> Iterator[Callable[..., QtWidgets.QMainWindow]]:
    """Builds main windows on ``settings``; each is closed (devices stopped) and deleted."""
    from ui.app import build_window
    from ui.state import UiState

    monkeypatch.setattr("ui.mission.page.ask", lambda *args: True)
    windows: list[QtWidgets.QMainWindow] = []

    def make(**kwargs: object) -> QtWidgets.QMainWindow:
        kwargs.setdefault("ui_state", UiState(tmp_path / "ui.ini"))
        kwargs.setdefault("settings_path", tmp_path / "settings.yaml")
        window = build_window(settings, **kwargs)  # type: ignore[arg-type]
        window.show()
        windows.append(window)
        return window

    yield make
    for window in windows:
        window.close()
        shiboken6.delete(window)  # now: a deleteLater outside an event loop may never run
    windows.clear()
    _flush_deletes()
