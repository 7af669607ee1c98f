"""The plant table says how each plant was found: splits, ambiguous plants, the plot's merges."""

from __future__ import annotations

from PySide6 import QtCore, QtGui

from fieldapp.recon.plants import MEETS_NOTE
from fieldapp.results.files import PlantRecord
from ui.results.tables import FOUND_COLUMN, PLANT_COLUMNS, PlantTableModel

REPORT = {
    "plant_search": {
        "plants": [
            {"plant": 1, "from_stem": True, "ambiguous_share": 0.0, "flagged": False,
             "grid_cell": [1, 1]},
            {"plant": 2, "from_stem": True, "ambiguous_share": 0.021, "flagged": True,
             "grid_cell": [1, 2]},
            {"plant": 3, "from_stem": True, "ambiguous_share": 0.002, "flagged": False,
             "grid_cell": None},
            {"plant": 4, "from_stem": False, "ambiguous_share": 0.0, "flagged": False,
             "grid_cell": [2, 2]},
        ],
        "splits": [{"plants": [2, 3]}],
        "merges": ["2 stem candidates merged into a stronger stem nearby"],
        "missing_cells": [[2, 1]],
        "extra_plants": [3],
    }
}  # fmt: skip


def _records() -> list[PlantRecord]:
    return [PlantRecord(i, 0.1 * i, 0.2, 60.0, 90.0, 1000) for i in range(1, 5)]


def _cell(model: PlantTableModel, row: int, role: QtCore.Qt.ItemDataRole) -> str:
    return str(model.index(row, FOUND_COLUMN).data(role))


def test_each_plant_says_how_it_was_found_with_the_details_in_its_tooltip(qtbot) -> None:
    model = PlantTableModel()
    model.set_plants(_records(), REPORT)
    assert model.columnCount() == len(PLANT_COLUMNS) and PLANT_COLUMNS[FOUND_COLUMN] == "found"
    display, tip = QtCore.Qt.ItemDataRole.DisplayRole, QtCore.Qt.ItemDataRole.ToolTipRole
    assert [_cell(model, r, display) for r in range(4)] == [
        "stem",
        "⚠ 2.1 % ambiguous",
        "split",
        "cluster",
    ]
    assert "joined to plant 3" in _cell(model, 1, tip) and "check this plant" in _cell(
        model, 1, tip
    )
    assert "joined to plant 2" in _cell(model, 2, tip) and "extra plant" in _cell(model, 2, tip)
    assert "row 1, column 1" in _cell(model, 0, tip)
    assert "no stem seen" in _cell(model, 3, tip)
    header = model.headerData(FOUND_COLUMN, QtCore.Qt.Orientation.Horizontal, tip)
    assert "2 stem candidates merged" in header and "row 2 column 1" in header


def test_results_without_a_plant_search_still_show_their_plants(qtbot) -> None:
    model = PlantTableModel()
    model.set_plants(_records(), {})
    assert model.rowCount() == 4
    assert _cell(model, 0, QtCore.Qt.ItemDataRole.DisplayRole) == "-"


def test_a_plant_with_a_caution_is_flagged_with_it_in_its_tooltip(qtbot) -> None:
    report = {
        "plant_search": {
            "plants": [
                {"plant": 1, "from_stem": True, "ambiguous_share": 0.0, "flagged": False,
                 "cautions": ["may be taller than measured: its top is where the views stop "
                              "seeing (top 114 cm, views reach 115 cm)"]},
                {"plant": 2, "from_stem": True, "ambiguous_share": 0.021, "flagged": True,
                 "cautions": ["seen only from farther stations, traits may be low (station 9; "
                              "nearest read 1.2 m)"]},
                {"plant": 3, "from_stem": True, "ambiguous_share": 0.0, "flagged": False,
                 "cautions": []},
                {"plant": 4, "from_stem": True, "ambiguous_share": 0.0, "flagged": False,
                 "cautions": [f"{MEETS_NOTE} 12"]},
            ],
        }
    }  # fmt: skip
    model = PlantTableModel()
    model.set_plants(_records()[:4], report)
    display, tip = QtCore.Qt.ItemDataRole.DisplayRole, QtCore.Qt.ItemDataRole.ToolTipRole
    assert [_cell(model, r, display) for r in range(4)] == [
        "⚠ may be taller than measured",
        "⚠ 2.1 % ambiguous",  # the ambiguity badge first; the caution in the tooltip
        "stem",
        "⚠ width meets plant 12",  # which plant, in a badge as short as the others
    ]
    assert "views reach 115 cm" in _cell(model, 0, tip)
    assert "station 9" in _cell(model, 1, tip)
    assert f"{MEETS_NOTE} 12" in _cell(model, 3, tip)
    orange = QtGui.QColor(190, 90, 0)
    drawn = [model.item(r, FOUND_COLUMN).foreground().color() == orange for r in range(4)]
    assert drawn == [True, True, False, True]  # flagged plants in orange
