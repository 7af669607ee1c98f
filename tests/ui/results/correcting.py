"""What the correction tests share: open a copy of a plot, select plants in the table, wait
for a correction to be applied, the table's plants."""

from __future__ import annotations

import shutil
from pathlib import Path

from PySide6 import QtCore


def open_copy(panel, plots: dict[str, Path], name: str, tmp_path: Path) -> Path:
    """Open a copy of ``plots[name]`` (in ``tmp_path``) in ``panel``; returns the copy."""
    folder = Path(shutil.copytree(plots[name], tmp_path / name))
    panel.open_results(folder)
    return folder


def select(panel, *plants: int) -> None:
    """Select the table rows of ``plants``, as ctrl-clicks would."""
    selection = panel.table.selectionModel()
    selection.clearSelection()
    for plant in plants:
        row = panel.proxy.mapFromSource(panel.plant_model.index(panel.plant_model.row_of(plant), 0))
        selection.select(
            row,
            QtCore.QItemSelectionModel.SelectionFlag.Select
            | QtCore.QItemSelectionModel.SelectionFlag.Rows,
        )


def settled(qtbot, panel) -> None:
    """Wait for the correction being applied (a hang guard, not a speed check)."""
    qtbot.waitUntil(lambda: not panel.correction.workers.busy, timeout=60_000)


def table(panel) -> dict:
    """The plants in the table by number."""
    return {p.plant: p for p in panel.plant_model.plants}
