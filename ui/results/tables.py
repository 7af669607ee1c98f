"""The plant table (id, position, height, width, points, how the plant was found) and the
per-station registration quality table, as Qt item models over plain records."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from PySide6 import QtCore, QtGui

from fieldapp.results.files import PlantRecord
from fieldapp.results.organ_tables import LEAF_TRAITS

PLANT_COLUMNS = ("plant", "x (m)", "y (m)", "height (cm)", "width (cm)", "points", "found")
FOUND_COLUMN = len(PLANT_COLUMNS) - 1
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

    def set_plants(self, plants: list[PlantRecord], report: dict[str, Any] | None = None) -> None:
        """The plants, and from ``report.json`` (when given) how each was found (column
        "found": a badge, the details in its tooltip; the plot's merges in the header's)."""
        self.removeRows(0, self.rowCount())
        self.plants = list(plants)
        notes = plant_search_notes(report or {})
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
            row.append(_found_item(notes.get(p.plant)))
            self.appendRow(row)
        self.setHeaderData(
            FOUND_COLUMN,
            QtCore.Qt.Orientation.Horizontal,
            merges_text(report or {}),
            Role.ToolTipRole,
        )

    def row_of(self, plant: int) -> int | None:
        for row, record in enumerate(self.plants):
            if record.plant == plant:
                return row
        return None


@dataclass(frozen=True)
class SearchNote:
    """How one plant was found, for the plant table: a short ``badge`` ("stem", "⚠ split",
    "⚠ 2.1 % ambiguous", "cluster") and the ``details`` for its tooltip; ``flagged`` plants
    are drawn in orange."""

    badge: str
    details: str
    flagged: bool


def plant_search_notes(report: dict[str, Any]) -> dict[int, SearchNote]:
    """Per plant id, from ``report.json``'s ``plant_search``: found from a stem or as a density
    cluster, the share of its points another stem reaches almost as soon (flagged above the
    report's bar), the plants whose canopy it shares (split by their stems), its cautions
    (flagged too: seen only from afar, from fewer sides or from one side only, a top the views
    may cut) and its grid cell.
    Empty when the report has no plant search (results from before it)."""
    search = report.get("plant_search") or {}
    groups: dict[int, list[int]] = {}
    for split in search.get("splits") or []:
        for plant in split.get("plants", []):
            groups[int(plant)] = [int(p) for p in split["plants"] if int(p) != int(plant)]
    extra = {int(p) for p in search.get("extra_plants") or []}
    notes = {}
    for entry in search.get("plants") or []:
        plant = int(entry["plant"])
        share = 100.0 * float(entry.get("ambiguous_share", 0.0))
        lines = [
            "found from its stem"
            if entry.get("from_stem", True)
            else "found as a density cluster (no stem seen)"
        ]
        badge = "stem" if entry.get("from_stem", True) else "cluster"
        if plant in groups:
            others = ", ".join(map(str, groups[plant]))
            lines.append(
                f"canopy joined to plant{'s' if len(groups[plant]) > 1 else ''} "
                f"{others}: split between them by their stems"
            )
            badge = "split"
        if share > 0.0:
            lines.append(f"{share:.1f} % of its points could belong to a neighbour")
        if entry.get("flagged"):
            badge = f"⚠ {share:.1f} % ambiguous"
            lines.append("check this plant: its traits may include a neighbour's leaf")
        cautions = [str(c) for c in entry.get("cautions") or []]
        lines.extend(cautions)
        if cautions and not entry.get("flagged"):
            badge = "⚠ " + _caution_badge(cautions[0])
        cell = entry.get("grid_cell")
        if cell:
            lines.append(f"planting grid row {cell[0]}, column {cell[1]}")
        elif plant in extra:
            lines.append("at no planting-grid cell (an extra plant)")
        flagged = bool(entry.get("flagged")) or bool(cautions)
        notes[plant] = SearchNote(badge, "\n".join(lines), flagged)
    return notes


_MEETS = re.compile(r"meets plant (\d+)$")
"""The end of the caution of a plant whose widest extent meets another
(``plants.MEETS_NOTE``, its wording before too)."""


def _caution_badge(caution: str) -> str:
    """A caution's short form for the "found" column (the whole of it in the tooltip): its
    first clause ("may be taller than measured", "seen only from farther stations"), or "width
    meets plant N" for a width that ends at another plant, whose first clause alone (as long
    as the column's other badges together) would say neither which plant nor why."""
    meets = _MEETS.search(caution)
    if meets:
        return f"width meets plant {meets.group(1)}"
    return caution.split(":")[0].split(",")[0]


def merges_text(report: dict[str, Any]) -> str:
    """The plot's merges and empty grid cells, one per line, for the "found" column's header."""
    search = report.get("plant_search") or {}
    lines = [str(m) for m in search.get("merges") or []]
    missing = search.get("missing_cells") or []
    if missing:
        cells = ", ".join(f"row {r} column {c}" for r, c in missing)
        lines.append(f"planting-grid cells without a plant: {cells}")
    return "\n".join(["how each plant was found", *lines])


def _found_item(note: SearchNote | None) -> QtGui.QStandardItem:
    item = QtGui.QStandardItem("-" if note is None else note.badge)
    item.setData("" if note is None else note.badge, Role.UserRole)
    item.setEditable(False)
    if note is not None:
        item.setToolTip(note.details)
        if note.flagged:
            item.setForeground(QtGui.QColor(190, 90, 0))
    return item


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
