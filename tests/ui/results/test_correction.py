"""Correcting plants in the results panel: merge the selected plants, split one by its stems,
delete, renumber, undo with Ctrl+Z; the table follows at once, the corrections are kept in the
folder and the results database and come back after a new reconstruction."""

from __future__ import annotations

import pytest
from PySide6 import QtCore

from fieldapp.errors import FieldappError
from fieldapp.results.corrections import read_corrections
from fieldapp.results.db import ResultsDB
from fieldapp.results.files import read_plants_csv
from ui.results.correction import CORRECTED_BRUSH
from ui.results.stem_picking import parse_stems

from ...fieldapp.results.seedlings import STEMS, seedlings, write_plot
from .correcting import open_copy as _open
from .correcting import select as _select
from .correcting import settled as _settled
from .correcting import table as _table


def test_merge_then_undo_with_ctrl_z(qtbot, panel, plots, tmp_path):
    folder = _open(panel, plots, "apart", tmp_path)
    bar = panel.correction
    assert not bar.undo_action.isEnabled()
    _select(panel, 1, 2)
    assert bar.selected_plants() == [1, 2]
    bar.merge_action.trigger()
    _settled(qtbot, panel)
    assert list(_table(panel)) == [1]
    assert _table(panel)[1] == read_plants_csv(folder / "plants.csv")[0]  # refreshed at once
    assert panel.plant_model.item(0, 3).background() == CORRECTED_BRUSH
    assert len(panel.view3d.scene.labels) == 1
    assert bar.undo_action.isEnabled() and "merge plants 1, 2" in bar.undo_action.toolTip()
    panel.show()
    panel.activateWindow()
    qtbot.waitUntil(panel.isActiveWindow)
    panel.table.setFocus()
    qtbot.keyClick(panel.table, QtCore.Qt.Key.Key_Z, QtCore.Qt.KeyboardModifier.ControlModifier)
    _settled(qtbot, panel)
    assert list(_table(panel)) == [1, 2]
    assert read_corrections(folder).operations == []


def test_split_by_stems_picked_then_delete_and_renumber(qtbot, panel, plots, tmp_path):
    folder = _open(panel, plots, "merged", tmp_path)
    bar = panel.correction
    _select(panel, 1)
    bar.split_action.trigger()
    assert not bar.split_row.isHidden()
    for x, y in STEMS:
        bar.add_stem(x, y)  # what a click on the map adds
    panel.select_plant(None)  # a click on the map may select another plant: still plant 1
    bar.split()
    _settled(qtbot, panel)
    assert list(_table(panel)) == [1, 2]
    assert _table(panel)[2].x_m == pytest.approx(STEMS[1][0], abs=0.02)
    _select(panel, 2)
    bar.number.setValue(12)
    bar.renumber_action.trigger()
    _settled(qtbot, panel)
    assert list(_table(panel)) == [1, 12]
    _select(panel, 1)
    bar.delete_action.trigger()
    _settled(qtbot, panel)
    assert list(_table(panel)) == [12]
    kinds = [op.kind for op in read_corrections(folder).operations]
    assert kinds == ["split", "relabel", "delete"]


def test_refusals_reach_the_error_sink(qtbot, panel, plots, tmp_path):
    _open(panel, plots, "apart", tmp_path)
    errors = []
    panel.error.connect(errors.append)
    _select(panel, 1)
    panel.correction.merge_action.trigger()
    assert errors and "select two or more" in errors[-1]
    _select(panel, 1)
    panel.correction.number.setValue(2)
    panel.correction.renumber_action.trigger()
    _settled(qtbot, panel)
    assert "taken" in errors[-1] and list(_table(panel)) == [1, 2]
    with pytest.raises(FieldappError, match=r"'0\.1' is not 'x, y'"):
        parse_stems("0.1, 0.2; 0.1 ; x")
    assert parse_stems("0.1, 0.2; 0.35 0.22") == [(0.1, 0.2), (0.35, 0.22)]


def test_corrections_come_back_after_a_new_reconstruction(qtbot, panel, plots, tmp_path):
    folder = _open(panel, plots, "apart", tmp_path)
    _select(panel, 1)
    panel.correction.delete_action.trigger()
    _settled(qtbot, panel)
    assert list(_table(panel)) == [2]
    with ResultsDB.open(panel.settings.paths.results_db) as db:
        assert db.corrections("s1") is not None  # kept for a re-run into another folder
    a, b = seedlings(0)
    write_plot(folder, [b, a], [1, 2])  # a new run into the same folder numbers them anew
    panel.open_results(folder)
    _settled(qtbot, panel)
    assert list(_table(panel)) == [1] and _table(panel)[1].x_m == pytest.approx(0.3, abs=0.02)
    other = write_plot(tmp_path / "other", [a, b], [1, 2])  # and into another folder
    panel.open_results(other)
    panel.correction._reconstructed(None)  # what the runner's success calls
    _settled(qtbot, panel)
    assert list(_table(panel)) == [2]
    assert read_corrections(other) is not None
