"""Small simulated sessions, and the check that no test leaves a thread or a window behind."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from pathlib import Path

import pytest
from PySide6 import QtCore, QtWidgets

from fieldapp.cli import main


@pytest.fixture(scope="session")
def plot_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("results") / "plot"
    assert main(["simulate", "--out", str(folder), "--stations", "4,5", "--views", "0-3"]) == 0
    return folder


@pytest.fixture(autouse=True)
def no_leaks(qapp: QtWidgets.QApplication) -> Iterator[None]:
    """No worker still running and no new top-level widget (pyqtgraph's parentless menus
    included) once the test's widgets are gone."""
    before = set(qapp.topLevelWidgets())
    yield
    pool = QtCore.QThreadPool.globalInstance()
    assert pool.waitForDone(20_000), "a worker thread is still running"
    for widget in qapp.topLevelWidgets():
        if widget not in before and not isinstance(widget, QtWidgets.QMenu):
            widget.close()
            widget.deleteLater()
    for _ in range(3):
        gc.collect()
        QtCore.QCoreApplication.sendPostedEvents(None, QtCore.QEvent.Type.DeferredDelete)
        QtCore.QCoreApplication.processEvents()
    extra = [type(w).__name__ for w in qapp.topLevelWidgets() if w not in before]
    assert not extra, f"top-level widgets left: {extra}"
