"""The main window on simulated devices: pages, device states, the badge, notices for a
failed device, STOP on Esc, and what is remembered between runs."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from PySide6 import QtCore
from pytestqt.qtbot import QtBot

from devices.table import TableDisconnected
from fieldapp.rig import RigError
from fieldapp.settings import Settings
from ui.devices.hub import DeviceState, failed_device
from ui.main_window import MainWindow
from ui.state import UiState

pytestmark = pytest.mark.usefixtures("no_leaks")


def connected(window: MainWindow) -> bool:
    return window.context.hub.connected


def test_pages_and_badge_before_and_after_connecting(
    make_window: Callable[..., MainWindow], wait_until: Callable[..., bool]
) -> None:
    window = make_window()
    titles = [window.sidebar.item(i).text() for i in range(window.sidebar.count())]
    assert titles == ["Calibrate", "Mission", "Live", "Results"]
    assert not window.badge.isVisible()
    assert all(i.state is DeviceState.DISCONNECTED for i in window.status.indicators.values())
    window.connect_button.click()
    assert window.connect_button.text() == "Connecting..."
    assert wait_until(lambda: connected(window))
    states = {name: i.state for name, i in window.status.indicators.items()}
    assert states == dict.fromkeys(("camera", "table", "base"), DeviceState.SIMULATED)
    assert window.badge.isVisible()
    assert "Table: simulated" in window.status.indicators["table"].text()
    assert "pts" in window.status.indicators["table"].toolTip()  # the simulated Grbl's pty
    assert wait_until(lambda: "%" in window.status.battery.text(), 5.0)
    assert "GB free" in window.status.disk.text()
    assert window.connect_button.text() == "Disconnect"
    window.connect_button.click()
    assert wait_until(lambda: window.status.indicators["base"].state is DeviceState.DISCONNECTED)
    assert not window.badge.isVisible()


def test_a_failed_table_is_shown_with_its_advice(
    make_window: Callable[..., MainWindow], settings: Settings, wait_until: Callable[..., bool]
) -> None:
    settings.devices.table_port = "/dev/ttyUSB-fieldapp-absent"
    window = make_window()
    window.toggle_connection()
    assert wait_until(lambda: window.status.indicators["table"].state is DeviceState.ERROR)
    table = window.status.indicators["table"]
    assert "ttyUSB-fieldapp-absent" in table.toolTip()
    assert window.status.indicators["base"].state is DeviceState.DISCONNECTED
    cards = window.notices.cards()
    assert len(cards) == 1
    text = cards[0].label.text()
    assert "Devices not connected" in text and "ttyUSB-fieldapp-absent" in text
    assert "USB cable" in text  # the advice for a table that cannot be opened
    assert not window.context.hub.connected
    assert window.connect_button.isEnabled() and window.connect_button.text() == "Connect"


def test_failed_device_is_read_from_the_cause() -> None:
    error = RigError("table on /dev/x: gone")
    error.__cause__ = TableDisconnected("gone")
    assert failed_device(error) == "table"
    assert failed_device(RigError("base at tcp://x: offline")) == "base"
    assert failed_device(RuntimeError("?")) is None


def test_escape_stops_the_base_and_holds_the_table(
    make_window: Callable[..., MainWindow], qtbot: QtBot, wait_until: Callable[..., bool]
) -> None:
    window = make_window()
    window.toggle_connection()
    assert wait_until(lambda: connected(window))
    rig = window.context.hub.rig
    assert rig is not None and rig.sim_base is not None
    assert not rig.sim_base.latched
    window.show_page("results")
    window.activateWindow()
    qtbot.waitActive(window)
    obeyed: list[str] = []
    window.context.hub.stopped.connect(obeyed.append)
    qtbot.keyClick(window.sidebar, QtCore.Qt.Key.Key_Escape)
    assert wait_until(lambda: sorted(obeyed) == ["base", "table"], 10.0), obeyed
    assert rig.sim_base.latched
    assert rig.table.status().state in ("Idle", "Hold")


def test_window_remembers_page_and_folders(
    make_window: Callable[..., MainWindow], tmp_path: Path
) -> None:
    window = make_window()
    window.show_page("live")
    window.resize(770, 560)
    size = window.size()
    window.context.ui_state.set_last_folder("plans", tmp_path)
    window.close()
    again = make_window()
    assert again.current_page_key() == "live"
    assert again.size() == size
    assert UiState(tmp_path / "ui.ini").last_folder("plans") == tmp_path
    assert UiState(tmp_path / "ui.ini").last_folder("gone") == Path.home()
