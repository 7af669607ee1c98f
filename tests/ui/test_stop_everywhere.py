"""Esc and STOP act from any dialog or wizard: with a modal dialog open (which blocks every
other window), Esc still stops the mission and the devices, and the dialog's own STOP button,
drawn over the window's, does too. (QTest's clicks bypass modal blocking, so the blocked click
on the window's own button cannot be shown here; the floating button is what a real click
reaches.)"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from PySide6 import QtCore, QtWidgets
from pytestqt.qtbot import QtBot

from fieldapp.mission.events import MissionState, Outcome
from ui.main_window import MainWindow
from ui.mission.page import MissionPage
from ui.stop_everywhere import floating_stop

from .test_mission import connected_page

pytestmark = pytest.mark.usefixtures("no_leaks")

Wait = Callable[..., bool]


def modal_box(window: MainWindow) -> QtWidgets.QMessageBox:
    box = QtWidgets.QMessageBox(
        QtWidgets.QMessageBox.Icon.Question, "Question", "Carry on?", parent=window
    )
    box.setWindowModality(QtCore.Qt.WindowModality.ApplicationModal)
    return box


def test_esc_in_a_modal_dialog_stops_the_running_mission_and_the_devices(
    make_window: Callable[..., MainWindow], qtbot: QtBot, wait_until: Wait
) -> None:
    window, page = connected_page(make_window, wait_until)
    rig = window.context.hub.rig
    assert rig is not None and rig.sim_base is not None
    obeyed: list[str] = []
    window.context.hub.stopped.connect(obeyed.append)
    page.start_button.click()
    assert wait_until(lambda: page.progress.captured >= 1)
    box = modal_box(window)
    box.show()
    qtbot.waitExposed(box)
    assert QtWidgets.QApplication.activeModalWidget() is box
    qtbot.keyClick(box, QtCore.Qt.Key.Key_Escape)
    assert wait_until(lambda: page.result is not None, 20.0)
    assert page.result is not None and page.result.outcome in (Outcome.STOPPED, Outcome.COMPLETE)
    assert page.controller.state is MissionState.FINISHED
    assert wait_until(lambda: sorted(obeyed) == ["base", "table"], 10.0), obeyed
    assert rig.sim_base.latched
    assert box.isVisible()  # Esc was STOP, not "close the dialog"
    box.close()
    box.deleteLater()


def test_the_stop_button_works_while_a_modal_dialog_blocks_the_window(
    make_window: Callable[..., MainWindow], qtbot: QtBot, wait_until: Wait
) -> None:
    window, page = connected_page(make_window, wait_until)
    rig = window.context.hub.rig
    assert rig is not None and rig.sim_base is not None
    stops: list[bool] = []
    page.controller.state_changed.connect(
        lambda s: stops.append(True) if s is MissionState.STOPPING else None
    )
    seen: dict[str, object] = {}

    def inside_the_dialog() -> None:  # runs in the dialog's own event loop (exec)
        dialog = QtWidgets.QApplication.activeModalWidget()
        assert isinstance(dialog, QtWidgets.QDialog)
        button = floating_stop(dialog)
        assert button is not None and button.isVisible()
        seen["over_stop"] = button.geometry().topLeft() == window.stop_button.mapToGlobal(
            QtCore.QPoint(0, 0)
        )
        seen["running"] = not stops
        qtbot.mouseClick(button, QtCore.Qt.MouseButton.LeftButton)
        seen["stopped"] = wait_until(lambda: page.result is not None, 20.0)
        dialog.reject()

    page.start_button.click()
    assert wait_until(lambda: page.progress.captured >= 1)
    QtCore.QTimer.singleShot(0, inside_the_dialog)
    window.open_devices_dialog()  # modal: exec() returns once the dialog is closed
    assert seen == {"over_stop": True, "running": True, "stopped": True}
    assert page.result is not None and page.result.outcome in (Outcome.STOPPED, Outcome.COMPLETE)
    assert rig.sim_base.latched


def test_esc_in_a_wizard_stops_and_keeps_the_wizard_open(
    make_window: Callable[..., MainWindow], qtbot: QtBot, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A calibration wizard is a page of the window: Esc in it is STOP, the wizard stays on
    its step, and the window's own STOP button is the one to click (no floating copy)."""
    window = make_window()
    calls: list[str] = []
    monkeypatch.setattr(window.context.hub, "emergency_stop", lambda: calls.append("stop"))
    window.show_page("calibrate")
    calibrate = window.pages["calibrate"]
    wizard = calibrate.open_wizard("views")  # type: ignore[attr-defined]
    qtbot.waitExposed(wizard)
    wizard.next()
    step = wizard.currentId()
    qtbot.keyClick(wizard.currentPage(), QtCore.Qt.Key.Key_Escape)
    assert calls == ["stop"] and wizard.isVisible() and wizard.currentId() == step
    assert floating_stop(wizard) is None and window.stop_button.isVisible()
    qtbot.mouseClick(window.stop_button, QtCore.Qt.MouseButton.LeftButton)
    assert calls == ["stop", "stop"]
    window.show_page("mission")  # another page and back: the wizard as it was left
    window.show_page("calibrate")
    assert calibrate.wizard is wizard and wizard.currentId() == step  # type: ignore[attr-defined]
    wizard.reject()


def test_esc_still_closes_a_popup_after_stopping(
    make_window: Callable[..., MainWindow], qtbot: QtBot, monkeypatch: pytest.MonkeyPatch
) -> None:
    window = make_window()
    calls: list[str] = []
    monkeypatch.setattr(window.context.hub, "emergency_stop", lambda: calls.append("stop"))
    page = window.pages["mission"]
    assert isinstance(page, MissionPage)
    menu = QtWidgets.QMenu(window)
    menu.addAction("one")
    menu.popup(window.mapToGlobal(QtCore.QPoint(10, 10)))
    qtbot.waitExposed(menu)
    qtbot.keyClick(menu, QtCore.Qt.Key.Key_Escape)
    assert calls == ["stop"]
    assert wait_for_hidden(menu)
    menu.deleteLater()


def wait_for_hidden(widget: QtWidgets.QWidget) -> bool:
    for _ in range(100):
        QtCore.QCoreApplication.processEvents()
        if not widget.isVisible():
            return True
        QtCore.QThread.msleep(10)
    return False
