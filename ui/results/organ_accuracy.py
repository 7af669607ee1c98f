"""Organ accuracy: the organ traits (leaf count, every leaf trait, stem diameter) against
hand-measured leaves or the simulator's truth, with the figures of the height and width
(R², RMSE, MAPE, bias and Bland-Altman limits) and a scatter of one trait with the 1:1 line.

The evaluation is :func:`fieldapp.evaluate.organ_files.evaluate_organ_references`, the one
``fieldapp evaluate organs`` and the HTML report run. A results folder reconstructed from a
simulated session (``truth.json`` in the session folder) is compared with its truth at once.
"""

from __future__ import annotations

from pathlib import Path

import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.evaluate.metrics import Agreement
from fieldapp.evaluate.organ_files import evaluate_organ_references
from fieldapp.evaluate.organs import UNITS, OrganEvaluation
from ui.results.data import PlotResults

COLUMNS = ("trait", "level", "n", "R²", "RMSE", "MAPE (%)", "bias", "95 % limits")


def agreement_cells(trait: str, level: str, a: Agreement) -> list[str]:
    """One row of the table: figures in the trait's unit, ``n/a`` where not defined."""

    def fmt(value: float | None, digits: int = 2) -> str:
        return "n/a" if value is None else f"{value:.{digits}f}"

    return [
        f"{trait} ({UNITS[trait]})",
        level,
        str(a.n),
        fmt(a.r2, 3),
        fmt(a.rmse),
        fmt(a.mape_percent, 1),
        fmt(a.bias),
        f"{fmt(a.loa_low)} .. {fmt(a.loa_high)}",
    ]


def counts_text(evaluation: OrganEvaluation, source: str) -> str:
    return (
        f"Against {source}: leaf count exact on {evaluation.count_exact} of "
        f"{len(evaluation.pairs)} plants; {evaluation.extra} leaves found but not in the "
        f"reference, {evaluation.missed} reference leaves not found."
    )


class OrganAccuracyPanel(QtWidgets.QWidget):
    """``evaluated(OrganEvaluation | None)`` whenever the comparison changes."""

    evaluated = QtCore.Signal(object)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.results_dir: Path | None = None
        self.evaluation: OrganEvaluation | None = None
        self.manual_button = QtWidgets.QPushButton("Hand-measured leaves…")
        self.manual_button.setToolTip(
            "a CSV with leaves.csv's columns: plant_id, leaf_id (from the bottom), then any of "
            "the traits (an empty cell is not measured)"
        )
        self.manual_button.clicked.connect(self._ask_manual)
        self.truth_button = QtWidgets.QPushButton("Simulator truth…")
        self.truth_button.clicked.connect(self._ask_truth)
        self.status = QtWidgets.QLabel("Open results with organs measured.")
        self.status.setWordWrap(True)
        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(list(COLUMNS))
        self.table.verticalHeader().hide()
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.itemSelectionChanged.connect(self._draw_selected)
        self.plot = pg.PlotWidget(background="w")
        self.plot.showGrid(x=True, y=True, alpha=0.3)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(self.manual_button)
        top.addWidget(self.truth_button)
        top.addStretch(1)
        body = QtWidgets.QHBoxLayout()
        body.addWidget(self.table, 3)
        body.addWidget(self.plot, 2)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.status)
        layout.addLayout(body, 1)
        self._set_enabled(False)

    def set_results(self, results: PlotResults) -> None:
        """A new plot: compared with its simulator's truth when its session has one."""
        self.results_dir = results.results_dir
        self._show(None, "")
        if not (results.results_dir / "leaves.csv").is_file():
            self._set_enabled(False)
            self.status.setText("Organs were not measured in this run (no leaves.csv).")
            return
        self._set_enabled(True)
        truth = results.session_folder / "truth.json" if results.session_folder else None
        if truth is not None and truth.is_file():
            self._try(lambda: self.compare(truth=truth))
        else:
            self.status.setText("Import hand-measured leaves (or a simulator's truth.json).")

    def compare(self, truth: Path | None = None, manual_leaves: Path | None = None) -> None:
        """Compare the plot's organs with ``truth`` or ``manual_leaves``; a bad file raises
        :class:`FieldappError` naming it (the figures shown before stay)."""
        if self.results_dir is None:
            raise FieldappError("open results first")
        evaluation, warnings = evaluate_organ_references(self.results_dir, truth, manual_leaves)
        source = "the simulator's truth" if truth is not None else f"{manual_leaves}"
        self._show(evaluation, "\n".join([counts_text(evaluation, source), *warnings]))

    def _show(self, evaluation: OrganEvaluation | None, text: str) -> None:
        self.evaluation = evaluation
        rows = evaluation.agreements() if evaluation is not None else []
        self.table.setRowCount(len(rows))
        for row, (trait, level, a) in enumerate(rows):
            for column, cell in enumerate(agreement_cells(trait, level, a)):
                item = QtWidgets.QTableWidgetItem(cell)
                item.setData(QtCore.Qt.ItemDataRole.UserRole, trait)
                self.table.setItem(row, column, item)
        self.table.resizeColumnsToContents()
        self.status.setText(text)
        self.plot.clear()
        if rows:
            self.table.selectRow(0)
        self.evaluated.emit(evaluation)

    def _draw_selected(self) -> None:
        """The selected trait's scatter: algorithm against reference, with the 1:1 line."""
        self.plot.clear()
        items = self.table.selectedItems()
        if self.evaluation is None or not items:
            return
        trait = str(items[0].data(QtCore.Qt.ItemDataRole.UserRole))
        algorithm, reference = self.evaluation.values(trait)
        values = [*algorithm, *reference] or [0.0, 1.0]
        low, high = min(values), max(values)
        pad = 0.05 * (high - low or 1.0)
        self.plot.plot([low - pad, high + pad], [low - pad, high + pad], pen=pg.mkPen("k"))
        self.plot.plot(
            reference, algorithm, pen=None, symbol="o", symbolSize=7, symbolBrush=(40, 160, 60)
        )
        self.plot.setLabel("bottom", f"reference {trait} ({UNITS[trait]})")
        self.plot.setLabel("left", f"algorithm {trait} ({UNITS[trait]})")

    def _set_enabled(self, enabled: bool) -> None:
        self.manual_button.setEnabled(enabled)
        self.truth_button.setEnabled(enabled)

    def _ask(self, title: str, pattern: str) -> Path | None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(self, title, "", pattern)
        return Path(name) if name else None

    def _ask_manual(self) -> None:
        path = self._ask("Hand-measured leaves", "CSV (*.csv)")
        if path is not None:
            self._try(lambda: self.compare(manual_leaves=path))

    def _ask_truth(self) -> None:
        path = self._ask("Simulator truth", "truth.json (*.json)")
        if path is not None:
            self._try(lambda: self.compare(truth=path))

    def _try(self, call: object) -> None:
        try:
            call()  # type: ignore[operator]
        except FieldappError as error:
            self.status.setText(f"⚠ {error}")
