"""Load, edit and save a mission plan (:class:`~fieldapp.mission.MissionPlan`).

The stations table lists the stations in visiting order (number, map x, y, yaw); the form
holds the views, frames per capture, settle time and quality policy. Every edit is validated
by the plan's own model: a valid plan is emitted with :attr:`PlanEditor.plan_changed`, an
invalid one shows the field and the reason.
"""

from __future__ import annotations

import logging
from pathlib import Path

from pydantic import ValidationError
from PySide6 import QtCore, QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.mission.plan import MissionPlan, StationPlan, default_plan, load_plan, save_plan
from ui.state import UiState

log = logging.getLogger(__name__)

COLUMNS = ("station", "x (m)", "y (m)", "yaw (deg)")


def describe(error: ValidationError) -> str:
    """The first problem of a validation error: ``field: message``."""
    problem = error.errors(include_url=False)[0]
    where = ".".join(str(part) for part in problem["loc"]) or "plan"
    return f"{where}: {problem['msg']}"


class PlanEditor(QtWidgets.QWidget):
    """Edits one plan; :meth:`plan` is the current valid plan."""

    plan_changed = QtCore.Signal(object)

    def __init__(self, ui_state: UiState, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.ui_state = ui_state
        self._plan = default_plan()
        self._loading = False
        self.path: Path | None = None
        self._build()
        self.set_plan(self._plan)

    def _build(self) -> None:
        self.name = QtWidgets.QLineEdit()
        self.view_count = QtWidgets.QSpinBox(minimum=1, maximum=360)
        self.view_step = QtWidgets.QDoubleSpinBox(minimum=0.1, maximum=360.0, decimals=1)
        self.frames = QtWidgets.QSpinBox(minimum=1, maximum=100)
        self.settle = QtWidgets.QDoubleSpinBox(minimum=0.0, maximum=60.0, decimals=1, suffix=" s")
        self.reference = QtWidgets.QSpinBox(minimum=1, maximum=999)
        self.keep_low = QtWidgets.QCheckBox("keep it, with a warning")
        self.keep_low.setToolTip(
            "A view still below the quality limits after its retries keeps its best attempt, "
            "with a warning, instead of stopping the mission."
        )
        form = QtWidgets.QFormLayout()
        form.addRow("Name", self.name)
        form.addRow("Views per station", self.view_count)
        form.addRow("Table step", self.view_step)
        form.addRow("Frames per capture", self.frames)
        form.addRow("Settle after a turn", self.settle)
        form.addRow("Reference station", self.reference)
        form.addRow("View below quality", self.keep_low)
        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.verticalHeader().setVisible(False)
        self.table.horizontalHeader().setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.Stretch)
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        for widget in (self.view_count, self.frames, self.reference):
            widget.valueChanged.connect(self._edited)
        for spin in (self.view_step, self.settle):
            spin.valueChanged.connect(self._edited)
        self.name.editingFinished.connect(self._edited)
        self.keep_low.toggled.connect(self._edited)
        self.table.itemChanged.connect(self._edited)
        self.error = QtWidgets.QLabel()
        self.error.setWordWrap(True)
        self.error.setStyleSheet("color:#c62828")
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(self._file_buttons())
        layout.addLayout(form)
        layout.addWidget(QtWidgets.QLabel("Stations in visiting order (map frame):"))
        layout.addWidget(self.table, 1)
        layout.addLayout(self._station_buttons())
        layout.addWidget(self.error)

    def _file_buttons(self) -> QtWidgets.QHBoxLayout:
        row = QtWidgets.QHBoxLayout()
        for text, slot in (("Load...", self.choose_and_load), ("Save as...", self.choose_and_save),
                           ("Paper's 3 x 3", self.reset_default)):  # fmt: skip
            button = QtWidgets.QPushButton(text)
            button.clicked.connect(slot)
            row.addWidget(button)
        return row

    def _station_buttons(self) -> QtWidgets.QHBoxLayout:
        row = QtWidgets.QHBoxLayout()
        for text, slot in (("Add", self.add_station), ("Remove", self.remove_station),
                           ("Up", lambda: self.move_station(-1)),
                           ("Down", lambda: self.move_station(1))):  # fmt: skip
            button = QtWidgets.QPushButton(text)
            button.clicked.connect(slot)
            row.addWidget(button)
        return row

    # --- plan <-> widgets -------------------------------------------------------------------

    def plan(self) -> MissionPlan:
        return self._plan

    def set_plan(self, plan: MissionPlan) -> None:
        self._loading = True
        try:
            self.name.setText(plan.name)
            self.view_count.setValue(plan.views.count)
            self.view_step.setValue(plan.views.step_deg)
            self.frames.setValue(plan.frames_per_capture)
            self.settle.setValue(plan.settle_s)
            self.reference.setValue(plan.reference_station)
            self.keep_low.setChecked(plan.keep_low_quality)
            self.table.setRowCount(len(plan.stations))
            for row, station in enumerate(plan.stations):
                self._set_row(row, station)
        finally:
            self._loading = False
        self._plan = plan
        self.error.clear()
        self.plan_changed.emit(plan)

    def _set_row(self, row: int, station: StationPlan) -> None:
        values = (
            str(station.number),
            f"{station.x_m:g}",
            f"{station.y_m:g}",
            f"{station.yaw_deg:g}",
        )
        for column, text in enumerate(values):
            self.table.setItem(row, column, QtWidgets.QTableWidgetItem(text))

    def _stations_from_table(self) -> list[dict[str, str]]:
        rows = []
        for row in range(self.table.rowCount()):
            cells = [self.table.item(row, c) for c in range(len(COLUMNS))]
            number, x, y, yaw = (c.text().strip() if c is not None else "" for c in cells)
            rows.append({"number": number, "x_m": x, "y_m": y, "yaw_deg": yaw})
        return rows

    def _edited(self) -> None:
        if self._loading:
            return
        document = self._plan.model_dump()
        document.update(
            name=self.name.text().strip(),
            frames_per_capture=self.frames.value(),
            settle_s=self.settle.value(),
            reference_station=self.reference.value(),
            keep_low_quality=self.keep_low.isChecked(),
            stations=self._stations_from_table(),
        )
        document["views"].update(count=self.view_count.value(), step_deg=self.view_step.value())
        try:
            plan = MissionPlan.model_validate(document)
        except ValidationError as error:
            self.error.setText(f"Plan not valid: {describe(error)}")
            return
        self.error.clear()
        self._plan = plan
        self.plan_changed.emit(plan)

    @property
    def valid(self) -> bool:
        return not self.error.text()

    # --- stations ---------------------------------------------------------------------------

    def add_station(self) -> None:
        numbers = [s.number for s in self._plan.stations]
        last = self._plan.stations[-1]
        row = self.table.rowCount()
        self._loading = True
        self.table.insertRow(row)
        self._set_row(row, StationPlan(number=max(numbers) + 1, x_m=last.x_m + 1.0, y_m=last.y_m))
        self._loading = False
        self._edited()

    def remove_station(self) -> None:
        row = self.table.currentRow()
        if row >= 0 and self.table.rowCount() > 1:
            self.table.removeRow(row)
            self._edited()

    def move_station(self, offset: int) -> None:
        row = self.table.currentRow()
        target = row + offset
        if row < 0 or not 0 <= target < self.table.rowCount():
            return
        stations = list(self._plan.stations)
        stations[row], stations[target] = stations[target], stations[row]
        self.set_plan(self._plan.model_copy(update={"stations": stations}))
        self.table.selectRow(target)

    # --- files ------------------------------------------------------------------------------

    def reset_default(self) -> None:
        self.path = None
        self.set_plan(default_plan(self._plan.devices))

    def choose_and_load(self) -> None:
        start = self.ui_state.last_folder("plans")
        name, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Load a mission plan", str(start), "Plans (*.yaml *.yml *.json)"
        )
        if name:
            self.ui_state.set_last_folder("plans", Path(name))
            self.load(Path(name))

    def load(self, path: Path) -> None:
        """Load ``path``; a bad file is shown (file and field), the current plan kept."""
        try:
            plan = load_plan(path)
        except FieldappError as error:
            self.error.setText(f"{path.name} not loaded: {error}")
            return
        self.path = path
        self.set_plan(plan)

    def choose_and_save(self) -> None:
        start = self.path or self.ui_state.last_folder("plans") / f"{self._plan.name}.yaml"
        name, _ = QtWidgets.QFileDialog.getSaveFileName(
            self, "Save the mission plan", str(start), "YAML (*.yaml);;JSON (*.json)"
        )
        if name:
            self.ui_state.set_last_folder("plans", Path(name))
            self.save(Path(name))

    def save(self, path: Path) -> None:
        try:
            save_plan(self._plan, path)
        except OSError as error:
            self.error.setText(f"{path} not saved: {error}")
            return
        self.path = path
