"""The status bar: each device's state, the base's battery, free disk space, and the
SIMULATED DEVICES badge whenever any device is simulated."""

from __future__ import annotations

import shutil
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from fieldapp.settings import BatterySettings
from ui.devices.hub import DEVICES, DeviceState, DeviceStatus

LOW_DISK_GB = 5.0

_COLOURS = {
    DeviceState.DISCONNECTED: "#8a8a8a",
    DeviceState.CONNECTING: "#d08a00",
    DeviceState.CONNECTED: "#2e8b3a",
    DeviceState.SIMULATED: "#6a4bc4",
    DeviceState.ERROR: "#c62828",
}

BADGE_STYLE = (
    "QLabel { background:#ffcc00; color:#222; font-weight:bold; padding:2px 10px;"
    " border:1px solid #b38f00; border-radius:3px; }"
)


def free_space_gb(path: Path) -> float:
    """Free space, in GB, on the disk holding ``path`` (its nearest existing parent)."""
    probe = path
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    return shutil.disk_usage(probe).free / 1e9


class DeviceIndicator(QtWidgets.QLabel):
    """``● Camera: simulated``, coloured by state; the tooltip says where or what failed."""

    def __init__(self, name: str, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.name = name
        self.state = DeviceState.DISCONNECTED
        self.show_status(DeviceStatus(name, DeviceState.DISCONNECTED))

    def show_status(self, status: DeviceStatus) -> None:
        self.state = status.state
        colour = _COLOURS[status.state]
        self.setText(
            f"<span style='color:{colour}'>●</span> {self.name.capitalize()}: {status.state.value}"
        )
        self.setToolTip(status.detail or status.state.value)


class SimulatedBadge(QtWidgets.QLabel):
    """``SIMULATED DEVICES``, shown while any device is simulated."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("SIMULATED DEVICES", parent)
        self.setStyleSheet(BADGE_STYLE)
        self.setToolTip("At least one device is simulated: nothing real moves or is seen.")
        self._simulated: set[str] = set()
        self.setVisible(False)

    @QtCore.Slot(object)
    def show_device(self, status: DeviceStatus) -> None:
        if status.state is DeviceState.SIMULATED:
            self._simulated.add(status.name)
        else:
            self._simulated.discard(status.name)
        self.setVisible(bool(self._simulated))
        self.setToolTip("Simulated: " + ", ".join(sorted(self._simulated)))


class StatusBar(QtWidgets.QStatusBar):
    """Device states on the left, battery and disk on the right."""

    def __init__(
        self,
        disk_path: Path,
        battery: BatterySettings | None = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.disk_path = disk_path
        self.battery_levels = battery or BatterySettings()
        self.indicators = {name: DeviceIndicator(name) for name in DEVICES}
        for indicator in self.indicators.values():
            self.addWidget(indicator)
        self.battery = QtWidgets.QLabel("Battery: -")
        self.disk = QtWidgets.QLabel("Disk: -")
        self.addPermanentWidget(self.battery)
        self.addPermanentWidget(self.disk)
        self._disk_timer = QtCore.QTimer(self)
        self._disk_timer.timeout.connect(self.refresh_disk)
        self._disk_timer.start(10_000)
        self.refresh_disk()

    @QtCore.Slot(object)
    def show_device(self, status: DeviceStatus) -> None:
        self.indicators[status.name].show_status(status)

    def set_battery(self, percent: float | None) -> None:
        """The base's level: orange at or below the warning level, red and bold at or below
        the critical one (the settings' ``battery``), as the missions judge it."""
        if percent is None:
            self.battery.setText("Battery: -")
            self.battery.setToolTip("")
            return
        levels = self.battery_levels
        style = "color:inherit"
        if percent <= levels.critical_pct:
            style = "color:#c62828; font-weight:bold"
        elif percent <= levels.warn_pct:
            style = "color:#ef6c00"
        self.battery.setText(f"<span style='{style}'>Battery: {percent:.0f} %</span>")
        self.battery.setToolTip(
            f"the base's battery; missions warn at {levels.warn_pct:.0f} % and stop at "
            f"{levels.critical_pct:.0f} % (settings: battery)"
        )

    @QtCore.Slot()
    def refresh_disk(self) -> None:
        try:
            free_gb = free_space_gb(self.disk_path)
        except OSError as error:
            self.disk.setText("Disk: ?")
            self.disk.setToolTip(str(error))
            return
        colour = "#c62828" if free_gb < LOW_DISK_GB else "inherit"
        self.disk.setText(f"<span style='color:{colour}'>Disk: {free_gb:.1f} GB free</span>")
        self.disk.setToolTip(f"free space on the disk holding {self.disk_path}")
