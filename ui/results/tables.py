"""The plant table (id, position, height, width, points) and the per-station registration
quality table, as Qt item models over plain records."""

from __future__ import annotations

from typing import Any

from PySide6 import QtCore, QtGui

from fieldapp.results.files import PlantRecord

PLANT_COLUMNS = ("plant", "x (m)", "y (m)", "height (cm)", "width (cm)", "points")
STATION_COLUMNS = ("station", "ICP accepted", "fitness", "RMSE (mm)", "correction (deg)", "note")
Role = QtCore.Qt.ItemDataRole


class PlantTableModel(QtCore.QAbstractTableModel):
    """One row per plant, sortable by any column (numbers sort as numbers)."""

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.plants: list[PlantRecord] = []

    def set_plants(self, plants: list[PlantRecord]) -> None:
        self.beginResetModel()
        self.plants = list(plants)
        self.endResetModel()

    def row_of(self, plant: int) -> int | None:
        for row, record in enumerate(self.plants):
            if record.plant == plant:
                return row
        return None

    def rowCount(self, parent: Any = QtCore.QModelIndex()) -> int:  # noqa: B008
        return 0 if parent.isValid() else len(self.plants)

    def columnCount(self, parent: Any = QtCore.QModelIndex()) -> int:  # noqa: B008
        return 0 if parent.isValid() else len(PLANT_COLUMNS)

    def headerData(self, section: int, orientation: QtCore.Qt.Orientation, role: int = 0) -> Any:
        if role == Role.DisplayRole and orientation == QtCore.Qt.Orientation.Horizontal:
            return PLANT_COLUMNS[section]
        return None

    def data(self, index: Any, role: int = 0) -> Any:
        if not index.isValid():
            return None
        p = self.plants[index.row()]
        values = (p.plant, p.x_m, p.y_m, p.height_cm, p.width_cm, p.points)
        value = values[index.column()]
        if role == Role.DisplayRole:
            digits = {1: 3, 2: 3, 3: 1, 4: 1}.get(index.column())
            return f"{value:.{digits}f}" if digits else str(value)
        if role == Role.UserRole:
            return value
        if role == Role.TextAlignmentRole:
            return int(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
        return None


def station_rows(report: dict[str, Any]) -> list[list[str]]:
    """The registration table's rows from ``report.json``'s ``stations``."""
    rows = []
    stations = report.get("stations") or {}
    for station, entry in sorted(stations.items(), key=lambda item: int(item[0])):
        rmse = entry.get("icp_rmse_m")
        fitness = entry.get("icp_fitness")
        rows.append(
            [
                str(station),
                "yes" if entry.get("icp_accepted") else "no",
                "-" if fitness is None else f"{fitness:.3f}",
                "-" if rmse is None else f"{1000 * rmse:.2f}",
                f"{entry.get('correction_rotation_deg', 0.0):.3f}",
                str(entry.get("message", "")),
            ]
        )
    return rows


def station_model(report: dict[str, Any], reference: int | None) -> QtGui.QStandardItemModel:
    model = QtGui.QStandardItemModel(0, len(STATION_COLUMNS))
    model.setHorizontalHeaderLabels(list(STATION_COLUMNS))
    for row in station_rows(report):
        items = [QtGui.QStandardItem(cell) for cell in row]
        if reference is not None and row[0] == str(reference):
            items[-1].setText(items[-1].text() or "reference station")
        elif row[1] == "no":
            for item in items:
                item.setForeground(QtGui.QColor(170, 70, 0))
        model.appendRow(items)
    return model
