"""Manual moves for setting up: jog the table, send the base to a pose or a station, and the
operator's recoveries (unlock, home, continue after a hold, reset the base's stop latch).
Every move runs on a worker; the result or the error comes back as a notice."""

from __future__ import annotations

import logging
import uuid
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from PySide6 import QtWidgets

from ui.workers import WorkerSet

if TYPE_CHECKING:
    from fieldapp.mission.plan import MissionPlan
    from fieldapp.rig import Rig
    from ui.context import AppContext

log = logging.getLogger(__name__)

MANUAL_GOTO_TIMEOUT_S = 120.0
NOT_CONNECTED = "Connect the devices to move them by hand."
READY = "Devices connected: turn the table or send the base where you need it."


def ask(parent: QtWidgets.QWidget, title: str, text: str) -> bool:
    """Yes/No question before the robot moves (tests replace it)."""
    answer = QtWidgets.QMessageBox.question(parent, title, text)
    return answer == QtWidgets.QMessageBox.StandardButton.Yes


def _spin(low: float, high: float, suffix: str, decimals: int = 2) -> QtWidgets.QDoubleSpinBox:
    spin = QtWidgets.QDoubleSpinBox()
    spin.setRange(low, high)
    spin.setDecimals(decimals)
    spin.setSuffix(suffix)
    return spin


class SetupPanel(QtWidgets.QWidget):
    """Table jog and base goto on the hub's rig; disabled while a mission runs."""

    def __init__(self, context: AppContext, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.context = context
        self._workers = WorkerSet()
        self.plan: MissionPlan | None = None
        self.last_result = ""
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self._table_group())
        layout.addWidget(self._base_group())
        self.result = QtWidgets.QLabel()
        self.result.setWordWrap(True)
        layout.addWidget(self.result)
        layout.addStretch(1)
        context.hub.state_changed.connect(lambda _status: self._show_connection())
        context.hub.rig_changed.connect(lambda _rig: self._show_connection())
        self._show_connection()

    def _show_connection(self) -> None:
        """Say what the panel can do now, unless it shows the last move's result."""
        if self.last_result and self.context.hub.connected:
            return
        self.last_result = ""
        self.result.setText(READY if self.context.hub.connected else NOT_CONNECTED)

    def _table_group(self) -> QtWidgets.QGroupBox:
        self.angle = _spin(-360.0, 360.0, " deg")
        self.step = _spin(0.1, 180.0, " deg", 1)
        self.step.setValue(45.0)
        grid = QtWidgets.QGridLayout()
        grid.addWidget(QtWidgets.QLabel("Angle"), 0, 0)
        grid.addWidget(self.angle, 0, 1)
        grid.addWidget(self._button("Turn to", self.turn_to), 0, 2)
        grid.addWidget(QtWidgets.QLabel("Jog by"), 1, 0)
        grid.addWidget(self.step, 1, 1)
        jog = QtWidgets.QHBoxLayout()
        jog.addWidget(self._button("−", lambda: self.jog(-1)))
        jog.addWidget(self._button("+", lambda: self.jog(1)))
        grid.addLayout(jog, 1, 2)
        recover = QtWidgets.QHBoxLayout()
        for text, method in (("Status", "status"), ("Unlock", "unlock"), ("Home", "home"),
                             ("Continue", "resume")):  # fmt: skip
            recover.addWidget(self._button(text, self._table_call(method)))
        grid.addLayout(recover, 2, 0, 1, 3)
        zero = QtWidgets.QHBoxLayout()  # docs/TABLE.md: a power-up counts from where it stands
        zero.addWidget(self._button("Park at zero", self.park_table))
        zero.addWidget(self._button("It is at its zero mark", self.confirm_table_zero))
        grid.addLayout(zero, 3, 0, 1, 3)
        group = QtWidgets.QGroupBox("Rotary table")
        group.setLayout(grid)
        return group

    def _base_group(self) -> QtWidgets.QGroupBox:
        self.x_m = _spin(-1000.0, 1000.0, " m")
        self.y_m = _spin(-1000.0, 1000.0, " m")
        self.yaw_deg = _spin(-180.0, 180.0, " deg", 1)
        self.station = QtWidgets.QComboBox()
        grid = QtWidgets.QGridLayout()
        for column, (label, spin) in enumerate(
            (("x", self.x_m), ("y", self.y_m), ("yaw", self.yaw_deg))
        ):
            grid.addWidget(QtWidgets.QLabel(label), 0, 2 * column)
            grid.addWidget(spin, 0, 2 * column + 1)
        grid.addWidget(self._button("Go to pose", self.goto_pose), 1, 0, 1, 2)
        grid.addWidget(self.station, 1, 2, 1, 2)
        grid.addWidget(self._button("Go to station", self.goto_station), 1, 4, 1, 2)
        grid.addWidget(self._button("Status", self.base_status), 2, 0, 1, 2)
        grid.addWidget(self._button("Reset stop latch", self.base_reset), 2, 2, 1, 4)
        group = QtWidgets.QGroupBox("Mobile base (map frame)")
        group.setLayout(grid)
        return group

    def _button(self, text: str, slot: Callable[[], None]) -> QtWidgets.QPushButton:
        button = QtWidgets.QPushButton(text)
        button.clicked.connect(slot)
        return button

    def show_plan(self, plan: MissionPlan) -> None:
        self.plan = plan
        self.station.clear()
        for station in plan.stations:
            self.station.addItem(f"station {station.number}", station.number)

    # --- actions ----------------------------------------------------------------------------

    def _run(self, title: str, action: Callable[[Rig], Any]) -> None:
        rig = self.context.hub.rig
        if rig is None:
            self.context.notifier.warn(title, "The devices are not connected.", "Press Connect.")
            return
        self.result.setText(f"{title}...")
        self._workers.run(
            lambda: action(rig), lambda r: self._done(title, r), lambda e: self._failed(title, e)
        )

    def _done(self, title: str, result: Any) -> None:
        self.last_result = f"{title}: {result}"
        self.result.setText(self.last_result)

    def _failed(self, title: str, error: BaseException) -> None:
        self.last_result = f"{title} failed: {error}"
        self.result.setText(f"<span style='color:#c62828'>{self.last_result}</span>")
        self.context.notifier.error(title, error)

    def turn_to(self) -> None:
        target = self.angle.value()
        self._run("Table", lambda rig: f"at {rig.table.goto_deg(target):.3f} deg")

    def jog(self, sign: int) -> None:
        step = sign * self.step.value()

        def move(rig: Rig) -> str:
            reached = rig.table.goto_deg(rig.table.position_deg() + step)
            return f"at {reached:.3f} deg"

        self._run("Table jog", move)

    def park_table(self) -> None:
        """Back to machine zero, where a controller reset by opening its port keeps angles."""
        self._run("Table park", lambda rig: f"at {rig.table.park():.3f} deg (machine zero)")

    def confirm_table_zero(self) -> None:
        """The operator turned the table to its zero mark by hand: its position is trusted."""

        def confirm(rig: Rig) -> str:
            rig.table.confirm_position_known()
            return f"confirmed: {rig.table.status()}"

        self._run("Table zero", confirm)

    def _table_call(self, method: str) -> Callable[[], None]:
        return lambda: self._run(f"Table {method}", lambda rig: getattr(rig.table, method)())

    def goto_pose(self) -> None:
        self._goto(self.x_m.value(), self.y_m.value(), self.yaw_deg.value(), "pose")

    def goto_station(self) -> None:
        if self.plan is None or self.station.currentData() is None:
            return
        station = self.plan.station(int(self.station.currentData()))
        self._goto(station.x_m, station.y_m, station.yaw_deg, f"station {station.number}")

    def _goto(self, x_m: float, y_m: float, yaw_deg: float, what: str) -> None:
        from devices.base.protocol import Pose

        if self.context.hub.rig is not None and not ask(
            self,
            "Move the base?",
            f"The base will drive to {what} (x {x_m:.2f} m, y {y_m:.2f} m, yaw {yaw_deg:.0f} "
            "deg in the map frame). Is the path clear of people and equipment?",
        ):
            return

        def go(rig: Rig) -> str:
            goal_id = f"manual-{uuid.uuid4().hex[:8]}"
            status = rig.base.goto(
                goal_id, Pose(x_m, y_m, yaw_deg), timeout_s=MANUAL_GOTO_TIMEOUT_S
            )
            pose = status.pose
            where = f"x {pose.x_m:.2f} m, y {pose.y_m:.2f} m, yaw {pose.yaw_deg:.0f} deg"
            return f"{status.state.value} at {where}"

        self._run(f"Base to {what}", go)

    def base_status(self) -> None:
        def read(rig: Rig) -> str:
            status = rig.base.status()
            return f"{status.state.value}, battery {status.battery_pct:.0f} %" + (
                f", {status.error}" if status.error else ""
            )

        self._run("Base", read)

    def base_reset(self) -> None:
        def reset(rig: Rig) -> str:
            rig.base.reset()
            return "stop latch cleared"

        self._run("Base reset", reset)

    @property
    def busy(self) -> bool:
        return self._workers.busy

    def shutdown(self) -> None:
        self._workers.wait(MANUAL_GOTO_TIMEOUT_S)
