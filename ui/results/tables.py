"""The plant table (id, position, height, width, points) and the per-station registration
quality table, as Qt item models over plain records."""

from __future__ import annotations

from typing import Any

from PySide6 import QtCore, QtGui

from fieldapp.results.files import PlantRecord
from fieldapp.results.organ_tables import LEAF_TRAITS

PLANT_COLUMNS = ("plant", "x (m)", "y (m)", "height (cm)", "width (cm)", "points")
LEAF_COLUMNS = (
    "leaf",
    "length (cm)",
    "max width (cm)",
    "area (cm²)",
    "angle from stem (°)",
    "azimuth (°)",
    "insertion (cm)",
)
STATION_COLUMNS = (
    "station",
    "ICP accepted",
    "verdict",
    "uncertainty (mm / deg)",
    "fitness",
    "RMSE (mm)",
    "correction (deg)",
    "note",
)
Role = QtCore.Qt.ItemDataRole


class PlantTableModel(QtGui.QStandardItemModel):
    """One row per plant; each cell's number is kept under ``UserRole`` for sorting."""

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(0, len(PLANT_COLUMNS), parent)
        self.setHorizontalHeaderLabels(list(PLANT_COLUMNS))
        self.plants: list[PlantRecord] = []

    def set_plants(self, plants: list[PlantRecord]) -> None:
        self.removeRows(0, self.rowCount())
        self.plants = list(plants)
        for p in self.plants:
            values = (p.plant, p.x_m, p.y_m, p.height_cm, p.width_cm, p.points)
            row = []
            for column, value in enumerate(values):
                digits = {1: 3, 2: 3, 3: 1, 4: 1}.get(column)
                item = QtGui.QStandardItem(f"{value:.{digits}f}" if digits else str(value))
                item.setData(value, Role.UserRole)
                item.setEditable(False)
                item.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignRight)
                row.append(item)
            self.appendRow(row)

    def row_of(self, plant: int) -> int | None:
        for row, record in enumerate(self.plants):
            if record.plant == plant:
                return row
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
                str(entry.get("verdict", "-")),
                uncertainty_text(entry),
                "-" if fitness is None else f"{fitness:.3f}",
                "-" if rmse is None else f"{1000 * rmse:.2f}",
                f"{entry.get('correction_rotation_deg', 0.0):.3f}",
                str(entry.get("message", "")),
            ]
        )
    return rows


def uncertainty_text(entry: dict[str, Any]) -> str:
    """A station's estimated uncertainty as ``"2.6 / 0.11"`` (mm / deg), ``-`` when unknown."""
    mm, deg = entry.get("uncertainty_mm"), entry.get("uncertainty_deg")
    return "-" if mm is None or deg is None else f"{mm:.1f} / {deg:.2f}"


def station_model(report: dict[str, Any], reference: int | None) -> QtGui.QStandardItemModel:
    model = QtGui.QStandardItemModel(0, len(STATION_COLUMNS))
    model.setHorizontalHeaderLabels(list(STATION_COLUMNS))
    for row in station_rows(report):
        items = [QtGui.QStandardItem(cell) for cell in row]
        if reference is not None and row[0] == str(reference):
            items[-1].setText(items[-1].text() or "reference station")
        elif row[2] == "unreliable":  # a warning the user cannot miss
            for item in items:
                item.setForeground(QtGui.QColor(255, 255, 255))
                item.setBackground(QtGui.QColor(190, 30, 30))
        elif row[1] == "no":
            for item in items:
                item.setForeground(QtGui.QColor(170, 70, 0))
        model.appendRow(items)
    return model


def leaf_model(leaves: list[dict[str, Any]]) -> QtGui.QStandardItemModel:
    """One row per leaf of a plant (``leaves.csv`` rows), from the bottom."""
    model = QtGui.QStandardItemModel(0, len(LEAF_COLUMNS))
    model.setHorizontalHeaderLabels(list(LEAF_COLUMNS))
    for leaf in sorted(leaves, key=lambda row: row["leaf_id"]):
        cells = [str(leaf["leaf_id"])]
        cells += ["-" if leaf.get(t) is None else f"{leaf[t]:.1f}" for t in LEAF_TRAITS]
        items = [QtGui.QStandardItem(cell) for cell in cells]
        for item in items:
            item.setEditable(False)
            item.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignRight)
        model.appendRow(items)
    return model
