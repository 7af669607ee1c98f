"""Ending the GUI's process (kill, Ctrl-C, a logout or shutdown) closes the window as the user
would, without asking: devices stopped, layout saved, exit 0. Before, SIGTERM and SIGINT were
ignored while Qt's event loop was idle."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from PySide6 import QtWidgets

from ui.main_window import MainWindow
from ui.quit_signals import QuitSignals


@pytest.mark.parametrize("number", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_reaches_the_qt_thread_and_the_handlers_come_back(
    qapp: QtWidgets.QApplication, wait_until: Callable[..., bool], number: int
) -> None:
    before = signal.getsignal(number)
    received: list[str] = []
    quitting = QuitSignals(received.append, [number])
    try:
        os.kill(os.getpid(), number)
        assert wait_until(lambda: received == [signal.Signals(number).name])
    finally:
        quitting.restore()
    assert signal.getsignal(number) is before


def test_closing_without_asking_stops_the_devices_and_asks_nothing(
    make_window: Callable[..., MainWindow], wait_until: Callable[..., bool]
) -> None:
    window = make_window()
    window.toggle_connection()
    assert wait_until(lambda: window.context.hub.connected)

    def never(parent: object) -> bool:
        raise AssertionError("asked while the process is being ended")

    for page in window.pages.values():
        if hasattr(page, "confirm_close"):
            page.confirm_close = never  # type: ignore[method-assign]
    window.close_without_asking("SIGTERM")
    assert not window.isVisible()
    assert not window.context.hub.connected


def test_the_gui_process_ends_cleanly_when_killed(tmp_path: Path) -> None:
    """The real command: once it says its handlers are in place (``-v``), SIGTERM closes it
    cleanly. No clock: each read blocks until the GUI writes, pytest-timeout guards a hang."""
    env = dict(os.environ)
    env.update(
        XDG_CONFIG_HOME=str(tmp_path / "config"),
        XDG_DATA_HOME=str(tmp_path / "data"),
        XDG_STATE_HOME=str(tmp_path / "state"),
        QT_QPA_PLATFORM="offscreen",
    )
    settings = str(tmp_path / "s.yaml")
    command = [sys.executable, "-m", "fieldapp", "-v", "gui", "--settings", settings]
    process = subprocess.Popen(command, env=env, stderr=subprocess.PIPE, text=True)
    said: list[str] = []
    try:
        assert process.stderr is not None
        ready = "SIGTERM, SIGINT, SIGHUP: the window closes, the devices stop"
        for line in process.stderr:  # until the handlers are in place, or the GUI ends
            said.append(line)
            if ready in line:
                break
        assert ready in said[-1], "".join(said)[-2000:]
        process.send_signal(signal.SIGTERM)
        _, rest = process.communicate()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    stderr = "".join(said) + rest
    assert process.returncode == 0, stderr[-2000:]
    assert "SIGTERM: closing the window, stopping the devices" in stderr
    assert "Traceback" not in stderr
