"""Build and run the field GUI: settings, device hub, notifier, main window."""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from fieldapp.settings import Settings, load_settings
from ui.context import AppContext
from ui.devices.hub import DeviceHub, RigOpener, default_opener
from ui.main_window import MainWindow
from ui.notifications import Level, Notice, Notifier
from ui.pages import PageSpec, default_pages
from ui.quit_signals import QuitSignals
from ui.state import UiState

log = logging.getLogger(__name__)

STARTUP_PROBE_ENV = "FIELDAPP_STARTUP_PROBE"
"""A file path: once the first window is shown, write when, and close (the start-up benchmark)."""
EXIT_WAIT_MS = 30_000
"""How long the closed application waits for background jobs still on Qt's thread pool."""
HEAVY_MODULES = ("open3d", "scipy", "matplotlib", "dask", "cv2", "sklearn", "small_gicp")
"""Imported only when used, never to show the first window."""

GIL_SWITCH_INTERVAL_S = 0.001
"""How often a thread holding the GIL is asked to hand it over (Python's default: 5 ms). The
device threads (camera grabber, simulators, mission) run Python too; a shorter interval lets
the GUI thread back in sooner. Measured by ``benchmarks/bench_gui_latency.py``: worst stall
during a mission 65 and 27 ms at 1 ms, against 229 and 111 ms at 5 ms (shared machine)."""


def tune_process() -> None:
    """Process-wide settings for a responsive GUI (call before starting device threads)."""
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)


class _NoticeHandler(logging.Handler):
    """Warnings logged while the settings load (bad fields) become notices."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


def load_settings_with_notices(path: Path | None) -> tuple[Settings, list[Notice]]:
    """The settings, and a warning notice for every field the loader had to drop."""
    handler = _NoticeHandler()
    logger = logging.getLogger("fieldapp.settings")
    logger.addHandler(handler)
    try:
        settings = load_settings(path)
    finally:
        logger.removeHandler(handler)
    notices = [
        Notice(Level.WARNING, "Settings", record.getMessage(), "Fix the field or remove it.")
        for record in handler.records
    ]
    return settings, notices


def build_window(
    settings: Settings,
    *,
    settings_path: Path | None = None,
    ui_state: UiState | None = None,
    opener: RigOpener = default_opener,
    pages: Sequence[PageSpec] | None = None,
) -> MainWindow:
    """The main window around a new hub and notifier (a QApplication must exist)."""
    notifier = Notifier()
    hub = DeviceHub(opener)
    context = AppContext(settings, hub, notifier, ui_state or UiState(), settings_path)
    window = MainWindow(context, default_pages() if pages is None else pages)
    notifier.setParent(window)
    hub.setParent(window)
    return window


def run_gui(settings_path: Path | None = None, connect: bool = True) -> int:
    """Open the window (connecting the configured devices, simulated by default); returns the
    exit code once it closes."""
    tune_process()
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    app.setApplicationName("fieldapp")
    settings, notices = load_settings_with_notices(settings_path)
    window = build_window(settings, settings_path=settings_path)
    for notice in notices:
        window.context.notifier.post(notice)
    window.show()
    probe = os.environ.get(STARTUP_PROBE_ENV)
    if probe:
        QtCore.QTimer.singleShot(0, lambda: _window_shown(Path(probe), window))
    elif connect:  # once the window is up: opening the rig loads the simulators (Open3D)
        QtCore.QTimer.singleShot(0, lambda: window.context.hub.connect_devices(settings.devices))
    quitting = QuitSignals(window.close_without_asking)  # kill, Ctrl-C, logout: devices stopped
    try:
        return int(app.exec())
    finally:
        quitting.restore()
        # No job may still run Python on a pool thread while the interpreter shuts down (an
        # abort at exit); the pages already waited for their own when the window closed.
        if not QtCore.QThreadPool.globalInstance().waitForDone(EXIT_WAIT_MS):
            log.warning("background work still running at exit")


def _window_shown(path: Path, window: QtWidgets.QWidget) -> None:
    """The startup probe (``benchmarks/bench_startup.py``): once the event loop has shown
    and painted the window, write the monotonic time (comparable across processes on Linux)
    and which heavy modules are loaded, then close."""
    heavy = sorted(name for name in HEAVY_MODULES if name in sys.modules)
    path.write_text(json.dumps({"shown_s": time.monotonic(), "heavy_modules": heavy}))
    window.close()
