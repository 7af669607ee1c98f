"""The guards behind every GUI test: ``no_widgets_off_gui_thread`` catches a widget read from a
worker or a Python thread, and stays quiet for the GUI thread and for plain data handed to a
worker; ``no_qt_thread_warnings`` catches Qt's own warnings of an object used across threads."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import pytest
from PySide6 import QtCore, QtWidgets

from ui.workers import Job

from .conftest import thread_warnings
from .thread_guard import ThreadGuard


def _run_worker(function: Callable[[], object], qtbot) -> None:
    ended: list[bool] = []
    Job(function, on_finished=lambda: ended.append(True)).start()
    qtbot.waitUntil(lambda: bool(ended), timeout=20_000)


def test_a_widget_read_from_a_worker_or_a_thread_is_caught(
    no_widgets_off_gui_thread: ThreadGuard, qtbot
) -> None:
    guard = no_widgets_off_gui_thread
    spin = QtWidgets.QSpinBox()
    qtbot.addWidget(spin)
    spin.value()  # the GUI thread: fine
    assert guard.violations == []
    _run_worker(spin.value, qtbot)  # a bound method handed to a worker
    _run_worker(lambda: spin.value() + 1, qtbot)
    thread = threading.Thread(target=lambda: spin.setValue(3), name="bad")
    thread.start()
    thread.join(20)
    caught = list(guard.violations)
    guard.violations.clear()  # caught on purpose: the fixture must not fail this test
    assert len(caught) == 3, caught
    assert sum("QSpinBox.value from thread" in v for v in caught) == 2
    assert any("QSpinBox.setValue from thread bad" in v for v in caught)


def test_plain_data_handed_to_a_worker_is_fine(
    no_widgets_off_gui_thread: ThreadGuard, qtbot
) -> None:
    spin = QtWidgets.QSpinBox()
    qtbot.addWidget(spin)
    value = spin.value()
    _run_worker(lambda: value * 2, qtbot)
    assert no_widgets_off_gui_thread.violations == []


@pytest.mark.qt_thread_warning_expected
def test_qt_warning_of_a_timer_started_from_another_thread_is_caught(qtlog: Any) -> None:
    timer = QtCore.QTimer()  # lives on the GUI thread
    thread = threading.Thread(target=lambda: timer.start(1000), name="bad")
    thread.start()
    thread.join(20)
    timer.deleteLater()
    found = thread_warnings([record.message for record in qtlog.records])
    assert any("Timers cannot be started from another thread" in m for m in found), found
