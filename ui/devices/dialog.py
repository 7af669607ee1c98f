"""The device settings dialog: each device simulated or real, each testable.

- camera: the backend (simulated, replay of a session folder, Kinect v2, RealSense);
- table: simulated, or a serial port from the ports present now (or typed: a path or a
  pyserial URL);
- base: simulated, or an endpoint and the folder holding the CURVE key files.

"Test" opens the device on a worker (:mod:`ui.devices.probe`) and shows what it answered,
or what failed and why, with the advice.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from pydantic import ValidationError
from PySide6 import QtCore, QtWidgets

from fieldapp.settings import DeviceSettings
from ui.devices.probe import ProbeResult, list_serial_ports, probe
from ui.state import UiState
from ui.workers import WorkerSet

SIMULATED = "Simulated"
CAMERA_BACKENDS = [
    ("sim", "Simulated Kinect v2"),
    ("replay", "Replay a session folder"),
    ("kinect2", "Kinect v2 (libfreenect2)"),
    ("realsense", "Intel RealSense"),
]


class PathField(QtWidgets.QWidget):
    """A line edit with a Browse button for a folder."""

    def __init__(self, ui_state: UiState, kind: str, placeholder: str) -> None:
        super().__init__()
        self.ui_state, self.kind = ui_state, kind
        self.edit = QtWidgets.QLineEdit(placeholderText=placeholder)
        browse = QtWidgets.QPushButton("Browse...")
        browse.clicked.connect(self._browse)
        row = QtWidgets.QHBoxLayout(self)
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(self.edit, 1)
        row.addWidget(browse)

    def path(self) -> Path | None:
        text = self.edit.text().strip()
        return Path(text) if text else None

    def set_path(self, path: Path | None) -> None:
        self.edit.setText("" if path is None else str(path))

    def _browse(self) -> None:
        start = self.path() or self.ui_state.last_folder(self.kind)
        name = QtWidgets.QFileDialog.getExistingDirectory(self, "Choose a folder", str(start))
        if name:
            self.ui_state.set_last_folder(self.kind, Path(name))
            self.edit.setText(name)


class ResultLabel(QtWidgets.QLabel):
    """What a test found: green when the device answered, red with the advice when not."""

    def __init__(self) -> None:
        super().__init__("not tested")
        self.setWordWrap(True)
        self.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.result: ProbeResult | None = None

    def show_testing(self) -> None:
        self.result = None
        self.setText("<span style='color:#d08a00'>testing...</span>")

    def show_result(self, result: ProbeResult) -> None:
        self.result = result
        if result.ok:
            self.setText(f"<span style='color:#2e8b3a'>✔ {result.message}</span>")
            return
        advice = f"<br><i>What to do:</i> {result.advice}" if result.advice else ""
        self.setText(f"<span style='color:#c62828'>✘ {result.message}</span>{advice}")


class DeviceSettingsDialog(QtWidgets.QDialog):
    """Edits a copy of :class:`DeviceSettings`; :meth:`result_settings` gives the new ones."""

    def __init__(
        self, devices: DeviceSettings, ui_state: UiState, parent: QtWidgets.QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle("Devices")
        self.setMinimumWidth(640)
        self.ui_state = ui_state
        self._workers = WorkerSet()
        self.results: dict[str, ResultLabel] = {}
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self._camera_group())
        layout.addWidget(self._table_group())
        layout.addWidget(self._base_group())
        self.realtime = QtWidgets.QCheckBox("Simulated devices move in real time (demos)")
        layout.addWidget(self.realtime)
        self.error = QtWidgets.QLabel()
        self.error.setStyleSheet("color:#c62828")
        layout.addWidget(self.error)
        buttons = QtWidgets.QDialogButtonBox(
            QtWidgets.QDialogButtonBox.StandardButton.Ok
            | QtWidgets.QDialogButtonBox.StandardButton.Cancel
        )
        self.test_all_button = buttons.addButton(
            "Test all", QtWidgets.QDialogButtonBox.ButtonRole.ActionRole
        )
        self.test_all_button.clicked.connect(self.test_all)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        layout.addWidget(buttons)
        self.load(devices)

    # --- groups -----------------------------------------------------------------------------

    def _group(self, title: str, device: str, form: QtWidgets.QFormLayout) -> QtWidgets.QGroupBox:
        group = QtWidgets.QGroupBox(title)
        test = QtWidgets.QPushButton(f"Test {device}")
        test.setObjectName(f"test_{device}")
        test.clicked.connect(lambda: self.test(device))
        self.results[device] = ResultLabel()
        form.addRow(test, self.results[device])
        group.setLayout(form)
        return group

    def _camera_group(self) -> QtWidgets.QGroupBox:
        self.camera_backend = QtWidgets.QComboBox()
        for key, label in CAMERA_BACKENDS:
            self.camera_backend.addItem(label, key)
        self.replay_session = PathField(self.ui_state, "sessions", "session folder to replay")
        self.camera_backend.currentIndexChanged.connect(self._backend_changed)
        form = QtWidgets.QFormLayout()
        form.addRow("Backend", self.camera_backend)
        form.addRow("Replay", self.replay_session)
        return self._group("Camera", "camera", form)

    def _table_group(self) -> QtWidgets.QGroupBox:
        self.table_port = QtWidgets.QComboBox(editable=True)
        line = self.table_port.lineEdit()
        if line is not None:
            line.setPlaceholderText("/dev/ttyUSB0 or socket://host:port")
        refresh = QtWidgets.QPushButton("Refresh ports")
        refresh.clicked.connect(self.refresh_ports)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.table_port, 1)
        row.addWidget(refresh)
        form = QtWidgets.QFormLayout()
        form.addRow("Serial port", row)
        return self._group("Rotary table (Grbl)", "table", form)

    def _base_group(self) -> QtWidgets.QGroupBox:
        self.base_simulated = QtWidgets.QCheckBox("Simulated base on this computer")
        self.base_endpoint = QtWidgets.QLineEdit(placeholderText="tcp://192.168.1.20:5555")
        self.base_keys = PathField(self.ui_state, "keys", "folder with client.key_secret")
        self.base_simulated.toggled.connect(self._base_mode_changed)
        form = QtWidgets.QFormLayout()
        form.addRow("", self.base_simulated)
        form.addRow("Endpoint", self.base_endpoint)
        form.addRow("Key folder", self.base_keys)
        return self._group("Mobile base (ZeroMQ)", "base", form)

    # --- values -----------------------------------------------------------------------------

    def load(self, devices: DeviceSettings) -> None:
        self.camera_backend.setCurrentIndex(
            max(0, self.camera_backend.findData(devices.camera_backend))
        )
        self.replay_session.set_path(devices.replay_session)
        self.refresh_ports(devices.table_port)
        self.base_simulated.setChecked(not devices.base_endpoint)
        self.base_endpoint.setText(devices.base_endpoint or "")
        self.base_keys.set_path(devices.base_keys_dir)
        self.realtime.setChecked(devices.realtime_simulation)
        self._backend_changed()
        self._base_mode_changed()

    def refresh_ports(self, selected: str | None = None) -> None:
        current = selected if isinstance(selected, str) else self._port_text()
        self.table_port.clear()
        self.table_port.addItem(SIMULATED, None)
        for path, description in list_serial_ports():
            self.table_port.addItem(f"{path} ({description})" if description else path, path)
        index = self.table_port.findData(current) if current else 0
        if index >= 0:
            self.table_port.setCurrentIndex(index)
        else:
            self.table_port.setEditText(str(current))

    def _port_text(self) -> str | None:
        index = self.table_port.currentIndex()
        text = self.table_port.currentText().strip()
        if index >= 0 and self.table_port.itemText(index) == text:
            data = self.table_port.itemData(index)
            return None if data is None else str(data)
        return None if text in ("", SIMULATED) else text

    def settings(self) -> DeviceSettings:
        """The dialog's choices; raises pydantic's ``ValidationError`` when one is invalid."""
        return DeviceSettings(
            camera_backend=self.camera_backend.currentData(),
            replay_session=self.replay_session.path(),
            table_port=self._port_text(),
            base_endpoint=None
            if self.base_simulated.isChecked()
            else (self.base_endpoint.text().strip() or None),
            base_keys_dir=self.base_keys.path(),
            realtime_simulation=self.realtime.isChecked(),
        )

    def result_settings(self) -> DeviceSettings:
        return self.settings()

    def accept(self) -> None:
        try:
            self.settings()
        except ValidationError as error:
            self.error.setText(f"Not saved: {error.errors(include_url=False)[0]['msg']}")
            return
        self._workers.wait()
        super().accept()

    def reject(self) -> None:
        self._workers.wait()
        super().reject()

    def _backend_changed(self) -> None:
        self.replay_session.setEnabled(self.camera_backend.currentData() == "replay")

    def _base_mode_changed(self) -> None:
        real = not self.base_simulated.isChecked()
        self.base_endpoint.setEnabled(real)
        self.base_keys.setEnabled(real)

    # --- tests ------------------------------------------------------------------------------

    def test(self, device: str) -> None:
        try:
            devices = self.settings()
        except ValidationError as error:
            self.error.setText(str(error.errors(include_url=False)[0]["msg"]))
            return
        label = self.results[device]
        label.show_testing()
        self._workers.run(
            lambda: probe(device, devices), self._shower(device), self._crashed(device)
        )

    def test_all(self) -> None:
        for device in self.results:
            self.test(device)

    def _shower(self, device: str) -> Callable[[ProbeResult], None]:
        def show(result: ProbeResult) -> None:
            self.results[device].show_result(result)
            self.adjustSize()

        return show

    def _crashed(self, device: str) -> Callable[[BaseException], None]:
        def show(error: BaseException) -> None:
            self.results[device].show_result(ProbeResult(device, False, str(error)))
            self.adjustSize()

        return show

    @property
    def testing(self) -> bool:
        return self._workers.busy
