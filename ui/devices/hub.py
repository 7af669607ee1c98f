"""The device hub: opens the rig (:func:`fieldapp.rig.open_rig`) on a worker thread, owns the
live :class:`~devices.camera.stream.FrameStream`, and turns the drivers' psygnal signals
(emitted on their reader threads) into Qt signals received on the GUI thread.

Every device has a :class:`DeviceState`; the status bar, the mission page and the live view
follow :attr:`DeviceHub.state_changed`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING

from PySide6 import QtCore

from ui.workers import WorkerSet

if TYPE_CHECKING:
    from devices.base.protocol import Pose, Status
    from devices.camera.stream import FrameStream
    from fieldapp.rig import Rig
    from fieldapp.settings import DeviceSettings

log = logging.getLogger(__name__)

DEVICES = ("camera", "table", "base")


class DeviceState(StrEnum):
    DISCONNECTED = "disconnected"
    CONNECTING = "connecting"
    CONNECTED = "connected"
    SIMULATED = "simulated"
    ERROR = "error"


@dataclass(frozen=True)
class DeviceStatus:
    """One device's state and a line saying where it is or what went wrong."""

    name: str
    state: DeviceState
    detail: str = ""


RigOpener = Callable[["DeviceSettings"], "Rig"]


def default_opener(devices: DeviceSettings) -> Rig:
    from fieldapp.rig import open_rig

    return open_rig(devices)


def failed_device(error: BaseException) -> str | None:
    """Which device (camera, table, base) an error from opening the rig is about."""
    from devices.base import BaseError
    from devices.camera import CameraError
    from devices.table import TableException

    cause = error.__cause__ or error
    kinds: list[tuple[type[BaseException], str]] = [
        (CameraError, "camera"),
        (TableException, "table"),
        (BaseError, "base"),
    ]
    for kind, name in kinds:
        if isinstance(cause, kind):
            return name
    text = str(error)
    return next((name for name in DEVICES if text.startswith(name)), None)


class DeviceHub(QtCore.QObject):
    """Opens and closes the rig; its signals are delivered on the GUI thread."""

    state_changed = QtCore.Signal(object)
    """:class:`DeviceStatus` of one device."""
    rig_changed = QtCore.Signal(object)
    """The open :class:`~fieldapp.rig.Rig`, or ``None`` once closed."""
    connect_failed = QtCore.Signal(object)
    """The exception that stopped the rig from opening."""
    pose_received = QtCore.Signal(object)
    """The base's :class:`~devices.base.protocol.Pose` (map frame), from telemetry."""
    base_status = QtCore.Signal(object)
    """The base's :class:`~devices.base.protocol.Status` (battery, state), from telemetry."""
    table_angle_deg = QtCore.Signal(float)
    table_alarm = QtCore.Signal(int, str)
    device_lost = QtCore.Signal(str, str)
    """(device, reason) when a connected device goes away."""
    stopped = QtCore.Signal(str)
    """A device obeyed STOP: ``"base"`` (stopped, latched) or ``"table"`` (held)."""
    stop_failed = QtCore.Signal(object)
    """The exception that kept a device from obeying STOP."""

    def __init__(
        self, opener: RigOpener = default_opener, parent: QtCore.QObject | None = None
    ) -> None:
        super().__init__(parent)
        self._opener = opener
        self._workers = WorkerSet()
        self.rig: Rig | None = None
        self.stream: FrameStream | None = None
        self.states = {name: DeviceStatus(name, DeviceState.DISCONNECTED) for name in DEVICES}
        self.device_lost.connect(self._on_lost)

    @property
    def busy(self) -> bool:
        return self._workers.busy

    @property
    def connected(self) -> bool:
        return self.rig is not None

    def connect_devices(self, devices: DeviceSettings) -> None:
        """Open the rig on a worker; ``rig_changed`` or ``connect_failed`` follows."""
        if self.rig is not None or self._workers.busy:
            return
        for name in DEVICES:
            self._set(DeviceStatus(name, DeviceState.CONNECTING, "opening..."))
        self._workers.run(lambda: self._open(devices), self._opened, self._failed)

    def disconnect_devices(self, wait: bool = False) -> None:
        """Stop the stream and close the rig (on a worker unless ``wait``)."""
        rig, stream = self.rig, self.stream
        self.rig, self.stream = None, None
        if rig is None:
            return
        self.rig_changed.emit(None)
        if wait:
            _close(rig, stream)
            self._closed()
        else:
            self._workers.run(lambda: _close(rig, stream), lambda _: self._closed())

    def emergency_stop(self) -> None:
        """Stop the base and hold the table at once, each on its own worker so neither waits
        for the other (a hold returns once the table stands still)."""
        rig = self.rig
        if rig is None:
            return
        self._workers.run(rig.base.stop, lambda _: self.stopped.emit("base"), self._stop_failed)
        self._workers.run(rig.table.hold, lambda _: self.stopped.emit("table"), self._stop_failed)

    def _stop_failed(self, error: BaseException) -> None:
        log.error("STOP not obeyed: %s", error)
        self.stop_failed.emit(error)

    def shutdown(self, timeout_s: float = 10.0) -> None:
        """Wait for pending work, then close everything now (window closing)."""
        self._workers.wait(timeout_s)
        self.disconnect_devices(wait=True)
        self._workers.wait(timeout_s)

    def _open(self, devices: DeviceSettings) -> tuple[Rig, FrameStream]:
        from devices.camera.stream import FrameStream

        rig = self._opener(devices)
        try:
            stream = FrameStream(rig.camera).start()
        except Exception:
            rig.close()
            raise
        return rig, stream

    def _opened(self, opened: tuple[Rig, FrameStream]) -> None:
        rig, stream = opened
        self.rig, self.stream = rig, stream
        rig.base.pose_received.connect(self._on_pose)
        rig.base.state_received.connect(self._on_base_status)
        rig.table.position_deg_changed.connect(self._on_table_angle)
        rig.table.alarm_raised.connect(self._on_table_alarm)
        rig.table.disconnected.connect(self._on_table_lost)
        for summary in rig.devices():
            state = DeviceState.SIMULATED if summary.simulated else DeviceState.CONNECTED
            self._set(DeviceStatus(summary.name, state, summary.where))
        self.rig_changed.emit(rig)

    def _failed(self, error: BaseException) -> None:
        bad = failed_device(error)
        for name in DEVICES:
            if name == bad or bad is None:
                self._set(DeviceStatus(name, DeviceState.ERROR, str(error)))
            else:
                self._set(DeviceStatus(name, DeviceState.DISCONNECTED, "not opened"))
        self.connect_failed.emit(error)

    def _closed(self) -> None:
        for name in DEVICES:
            self._set(DeviceStatus(name, DeviceState.DISCONNECTED))

    # psygnal callbacks: they run on the drivers' threads; Qt queues the signals to the GUI.

    def _on_pose(self, _t_s: float, pose: Pose) -> None:
        self.pose_received.emit(pose)

    def _on_base_status(self, status: Status) -> None:
        self.base_status.emit(status)

    def _on_table_angle(self, angle_deg: float) -> None:
        self.table_angle_deg.emit(angle_deg)

    def _on_table_alarm(self, code: int, meaning: str) -> None:
        self.table_alarm.emit(code, meaning)

    def _on_table_lost(self, reason: str) -> None:
        self.device_lost.emit("table", reason)

    @QtCore.Slot(str, str)
    def _on_lost(self, name: str, reason: str) -> None:
        if self.rig is not None:
            self._set(DeviceStatus(name, DeviceState.ERROR, f"lost: {reason}"))

    def _set(self, status: DeviceStatus) -> None:
        self.states[status.name] = status
        self.state_changed.emit(status)


def _close(rig: Rig, stream: FrameStream | None) -> None:
    if stream is not None:
        stream.stop()
    rig.close()
