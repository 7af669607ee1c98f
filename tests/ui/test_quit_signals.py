"""Ending the GUI's process (kill, Ctrl-C, a logout or shutdown) closes the window as the user
would, without asking: devices stopped, layout saved, exit 0. Before, SIGTERM and SIGINT were
ignored while Qt's event loop was idle."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from PySide6 import QtWidgets

from ui.main_window import MainWindow
from ui.quit_signals import QuitSignals

HANG_S = 120.0


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


def _catches(pid: int, number: int) -> bool:
    """Whether process ``pid`` has a handler for signal ``number`` (/proc's SigCgt mask)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (number - 1) & 1)
    return False


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux's /proc")
def test_the_gui_process_ends_cleanly_when_killed(tmp_path: Path) -> None:
    number = signal.SIGTERM
    env = dict(os.environ)
    env.update(
        XDG_CONFIG_HOME=str(tmp_path / "config"),
        XDG_DATA_HOME=str(tmp_path / "data"),
        XDG_STATE_HOME=str(tmp_path / "state"),
        QT_QPA_PLATFORM="offscreen",
    )
    command = [sys.executable, "-m", "fieldapp", "gui", "--settings", str(tmp_path / "s.yaml")]
    process = subprocess.Popen(command, env=env, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + HANG_S  # a hang guard, not a speed check
        # the window's handlers are in place once SIGTERM is caught (Python catches SIGINT
        # from its start)
        while not _catches(process.pid, signal.SIGTERM):
            assert process.poll() is None, process.communicate()[1][-2000:]
            assert time.monotonic() < deadline, "the GUI never installed its signal handlers"
            time.sleep(0.05)
        process.send_signal(number)
        _, stderr = process.communicate(timeout=HANG_S)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, stderr[-2000:]
    assert f"{signal.Signals(number).name}: closing the window, stopping the devices" in stderr
    assert "Traceback" not in stderr
