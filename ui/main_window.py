"""The main window: a side bar of pages (Calibrate, Mission, Live, Results), a header with the
device buttons, the SIMULATED DEVICES badge and the big STOP (Esc), one notification strip of
fixed height (its history in the Notices dock), the View and Help menus, and the status bar.
Geometry and the open page are remembered (QSettings)."""

from __future__ import annotations

import logging
from collections.abc import Sequence

from PySide6 import QtCore, QtGui, QtWidgets

from ui.context import AppContext
from ui.devices.hub import DeviceState, DeviceStatus
from ui.notice_area import NoticeLog, NotificationPanel
from ui.notifications import notice_from_error
from ui.pages import PageSpec
from ui.status import SimulatedBadge, StatusBar
from ui.stop_everywhere import StopEverywhere

log = logging.getLogger(__name__)

STOP_STYLE = (
    "QPushButton { background:#c62828; color:white; font-size:18px; font-weight:bold;"
    " padding:8px 22px; border-radius:6px; border:2px solid #7f0000; }"
    "QPushButton:pressed { background:#8e0000; }"
    "QPushButton:disabled { background:#d9a3a3; border-color:#c09090; }"
)


class MainWindow(QtWidgets.QMainWindow):
    """Hosts ``pages`` (see :mod:`ui.pages`) around the shared :class:`AppContext`."""

    def __init__(
        self,
        context: AppContext,
        pages: Sequence[PageSpec],
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.context = context
        self.setWindowTitle("fieldapp: maize seedling phenotyping")
        self.pages: dict[str, QtWidgets.QWidget] = {}
        self._asking_on_close = True  # False once the process is being ended (a signal)
        self._build(pages)
        self._wire()
        self._restore()

    # --- layout -----------------------------------------------------------------------------

    def _build(self, pages: Sequence[PageSpec]) -> None:
        self.sidebar = QtWidgets.QListWidget()
        self.sidebar.setObjectName("sidebar")
        self.sidebar.setFixedWidth(150)
        self.sidebar.setStyleSheet(
            "#sidebar { font-size:16px; background:#263238; color:#eceff1; border:none; }"
            "#sidebar::item { padding:14px 10px; }"
            "#sidebar::item:selected { background:#455a64; color:white; }"
            "#sidebar { outline:0; }"
        )
        self.stack = QtWidgets.QStackedWidget()
        for spec in pages:
            widget = spec.factory(self.context)
            self.pages[spec.key] = widget
            self.stack.addWidget(widget)
            item = QtWidgets.QListWidgetItem(spec.title)
            item.setData(QtCore.Qt.ItemDataRole.UserRole, spec.key)
            item.setToolTip(spec.tooltip)
            self.sidebar.addItem(item)
        self.sidebar.currentRowChanged.connect(self.stack.setCurrentIndex)
        self.notices = NotificationPanel(self.context.notifier)
        self.notices.log_requested.connect(self.show_log)
        body = QtWidgets.QWidget()
        column = QtWidgets.QVBoxLayout(body)
        column.setContentsMargins(8, 6, 8, 4)
        column.addWidget(self._header())
        column.addWidget(self.notices)
        column.addWidget(self.stack, 1)
        central = QtWidgets.QWidget()
        row = QtWidgets.QHBoxLayout(central)
        row.setContentsMargins(0, 0, 0, 0)
        row.setSpacing(0)
        row.addWidget(self.sidebar)
        row.addWidget(body, 1)
        self.setCentralWidget(central)
        settings = self.context.settings
        self.status = StatusBar(settings.paths.sessions_dir, settings.battery)
        self.setStatusBar(self.status)
        self._log_dock()
        self._menus()

    def _log_dock(self) -> None:
        self.log = NoticeLog(self.context.notifier)
        self.log_dock = QtWidgets.QDockWidget("Notices", self)
        self.log_dock.setObjectName("noticesDock")  # saveState/restoreState need a name
        self.log_dock.setWidget(self.log)
        self.addDockWidget(QtCore.Qt.DockWidgetArea.BottomDockWidgetArea, self.log_dock)
        self.log_dock.hide()

    def _menus(self) -> None:
        view = self.menuBar().addMenu("&View")
        notices = self.log_dock.toggleViewAction()
        notices.setText("&Notices log")
        notices.setShortcut(QtGui.QKeySequence("Ctrl+L"))
        view.addAction(notices)
        help_menu = self.menuBar().addMenu("&Help")
        about = help_menu.addAction("&About fieldapp")
        about.triggered.connect(self.show_about)

    @QtCore.Slot()
    def show_log(self) -> None:
        self.log_dock.show()
        self.log_dock.raise_()

    def about_text(self) -> str:
        from importlib.metadata import PackageNotFoundError, version

        try:
            release = version("fieldapp")
        except PackageNotFoundError:
            release = "unknown (not installed)"
        return (
            f"<b>fieldapp</b> {release}<br>Maize seedling phenotyping in the field: a Kinect v2 "
            "depth camera on a rotary table, carried by a mobile base; reconstruction and "
            "plant traits on the workstation.<br>Simulated devices are used until real ones "
            "are chosen in Devices..."
        )

    @QtCore.Slot()
    def show_about(self) -> None:
        QtWidgets.QMessageBox.about(self, "About fieldapp", self.about_text())

    def _header(self) -> QtWidgets.QWidget:
        header = QtWidgets.QWidget()
        row = QtWidgets.QHBoxLayout(header)
        row.setContentsMargins(0, 0, 0, 0)
        title = QtWidgets.QLabel("<span style='font-size:18px; font-weight:bold'>fieldapp</span>")
        self.badge = SimulatedBadge()
        self.devices_button = QtWidgets.QPushButton("Devices...")
        self.devices_button.setToolTip("Choose each device: simulated or real; test connections")
        self.connect_button = QtWidgets.QPushButton("Connect")
        self.connect_button.setMinimumWidth(110)
        self.stop_button = QtWidgets.QPushButton("STOP (Esc)")
        self.stop_button.setStyleSheet(STOP_STYLE)
        self.stop_button.setToolTip("Stop the base and hold the table now; aborts the mission")
        row.addWidget(title)
        row.addSpacing(12)
        row.addWidget(self.badge)
        row.addStretch(1)
        row.addWidget(self.devices_button)
        row.addWidget(self.connect_button)
        row.addSpacing(16)
        row.addWidget(self.stop_button)
        return header

    def _wire(self) -> None:
        hub = self.context.hub
        hub.state_changed.connect(self.status.show_device)
        hub.state_changed.connect(self.badge.show_device)
        hub.state_changed.connect(self._update_connect_button)
        hub.state_changed.connect(self._base_state)
        hub.base_status.connect(lambda status: self.status.set_battery(status.battery_pct))
        hub.connect_failed.connect(self._connect_failed)
        hub.device_lost.connect(self._device_lost)
        hub.table_alarm.connect(self._table_alarm)
        hub.stop_failed.connect(lambda error: self.context.notifier.error("STOP", error))
        self.connect_button.clicked.connect(self.toggle_connection)
        self.devices_button.clicked.connect(self.open_devices_dialog)
        self.stop_button.clicked.connect(self.emergency_stop)
        # Esc and STOP from every window, dialogs and wizards included (ui/stop_everywhere.py)
        self.stop_everywhere = StopEverywhere(self, self.stop_button, self.emergency_stop)
        finished = getattr(self.pages.get("mission"), "session_finished", None)
        if finished is not None:
            finished.connect(self._session_finished)

    # --- actions ----------------------------------------------------------------------------

    @QtCore.Slot()
    def toggle_connection(self) -> None:
        hub = self.context.hub
        if hub.connected:
            if self._mission_busy():
                self.context.notifier.warn(
                    "Disconnect", "A mission is running.", "Pause or abort it first."
                )
                return
            hub.disconnect_devices()
        else:
            hub.connect_devices(self.context.settings.devices)

    @QtCore.Slot()
    def emergency_stop(self) -> None:
        """Base stopped and table held at once, mission aborted (Esc, the STOP button)."""
        log.warning("STOP pressed")
        for page in self.pages.values():
            stop = getattr(page, "emergency_stop", None)
            if callable(stop):
                stop()
        self.context.hub.emergency_stop()

    @QtCore.Slot()
    def open_devices_dialog(self) -> None:
        from ui.devices.dialog import DeviceSettingsDialog

        dialog = DeviceSettingsDialog(self.context.settings.devices, self.context.ui_state, self)
        if dialog.exec() == QtWidgets.QDialog.DialogCode.Accepted:
            self.context.settings.devices = dialog.result_settings()
            self.context.save_settings()
            if self.context.hub.connected:
                self.context.notifier.info(
                    "Devices", "New device choices apply at the next Connect."
                )
        dialog.deleteLater()

    def _session_finished(self, folder: object) -> None:
        """Hand a finished mission's session to the Results page, when it can open one."""
        from pathlib import Path

        from fieldapp.errors import FieldappError

        open_session = getattr(self.pages.get("results"), "open_session", None)
        if not callable(open_session):
            return
        try:
            open_session(Path(str(folder)))
        except FieldappError as error:
            self.context.notifier.error("Results", error)

    def show_page(self, key: str) -> None:
        keys = list(self.pages)
        if key in keys:
            self.sidebar.setCurrentRow(keys.index(key))

    def current_page_key(self) -> str:
        return list(self.pages)[self.stack.currentIndex()]

    def _mission_busy(self) -> bool:
        return any(bool(getattr(page, "busy", False)) for page in self.pages.values())

    def _base_state(self, status: DeviceStatus) -> None:
        if status.name == "base" and status.state not in (
            DeviceState.CONNECTED,
            DeviceState.SIMULATED,
        ):
            self.status.set_battery(None)

    def _update_connect_button(self, _status: DeviceStatus) -> None:
        hub = self.context.hub
        states = {s.state for s in hub.states.values()}
        connecting = DeviceState.CONNECTING in states
        self.connect_button.setText(
            "Connecting..." if connecting else ("Disconnect" if hub.connected else "Connect")
        )
        self.connect_button.setEnabled(not connecting)

    def _connect_failed(self, error: BaseException) -> None:
        self.context.notifier.post(notice_from_error("Devices not connected", error))
        self._update_connect_button(DeviceStatus("camera", DeviceState.ERROR))

    def _device_lost(self, name: str, reason: str) -> None:
        self.context.notifier.warn(
            f"{name.capitalize()} lost", reason, "Check its cable and power, then reconnect."
        )

    def _table_alarm(self, code: int, meaning: str) -> None:
        self.context.notifier.warn(
            "Table alarm",
            f"ALARM:{code}: {meaning}",
            "Check the table is free to turn, then Unlock or Home it in Mission > Set-up.",
        )

    # --- state and closing ------------------------------------------------------------------

    def _restore(self) -> None:
        state = self.context.ui_state
        geometry = state.value_bytes("window/geometry")
        if geometry is None or not self.restoreGeometry(geometry):
            self.resize(1400, 900)
        layout = state.value_bytes("window/state")
        if layout is not None:
            self.restoreState(layout)
        self.show_page(state.text("window/page", "mission"))

    def _save_state(self) -> None:
        state = self.context.ui_state
        state.set_value("window/geometry", self.saveGeometry())
        state.set_value("window/state", self.saveState())
        state.set_value("window/page", self.current_page_key())
        state.sync()

    def close_without_asking(self, reason: str) -> None:
        """Close as the user would, but ask nothing (the process is being ended: ``reason``,
        e.g. "SIGTERM"): a running mission or move is stopped, the devices shut down, the
        layout saved."""
        log.warning("%s: closing the window, stopping the devices", reason)
        self._asking_on_close = False
        self.close()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:
        for page in self.pages.values():
            confirm = getattr(page, "confirm_close", None)
            if self._asking_on_close and callable(confirm) and not confirm(self):
                event.ignore()
                return
        self._save_state()
        for page in self.pages.values():
            shutdown = getattr(page, "shutdown", None)
            if callable(shutdown):
                shutdown()
        self.context.hub.shutdown()
        event.accept()
