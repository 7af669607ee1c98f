"""Manual measurements: the operator types (or imports from CSV) each plant's hand-measured
height and width; the accuracy figures (R2, RMSE, MAPE) and the scatter of algorithm against
manual values with the 1:1 line follow, as the paper's Figure 10."""

from __future__ import annotations

from pathlib import Path

import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.evaluate.metrics import Agreement
from fieldapp.evaluate.references import pair_with_manual
from fieldapp.evaluate.traits import TRAITS, TraitEvaluation, evaluate_traits
from fieldapp.results.files import ManualRecord, PlantRecord, read_manual_csv

COLUMNS = ("plant", "height (cm)", "manual height (cm)", "width (cm)", "manual width (cm)")
MANUAL_COLUMN = {"height": 2, "width": 4}


def parse_length(text: str, where: str) -> float | None:
    """A manual length in cm: empty means not measured; anything else must be a positive number."""
    text = text.strip().replace(",", ".")
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        raise FieldappError(f"{where}: {text!r} is not a number") from None
    if not 0.0 < value < 1000.0:
        raise FieldappError(f"{where}: {value:g} cm is not a plausible length")
    return value


def summary_text(trait: str, a: Agreement) -> str:
    def fmt(value: float | None, unit: str, digits: int) -> str:
        return "n/a" if value is None else f"{value:.{digits}f}{unit}"

    return (
        f"{trait}: n = {a.n}, R² = {fmt(a.r2, '', 3)}, RMSE = {fmt(a.rmse, ' cm', 2)}, "
        f"MAPE = {fmt(a.mape_percent, ' %', 1)}"
    )


class ManualPanel(QtWidgets.QWidget):
    """Manual values per plant and their agreement with the algorithm's."""

    evaluated = QtCore.Signal(object)
    """A :class:`TraitEvaluation`, or None when nothing can be compared."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.plants: list[PlantRecord] = []
        self.evaluation: TraitEvaluation | None = None
        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(list(COLUMNS))
        self.table.horizontalHeader().setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.Stretch)
        self.table.itemChanged.connect(self._changed)
        import_button = QtWidgets.QPushButton("Import CSV…")
        import_button.setToolTip(
            "a CSV with columns plant,height_cm,width_cm (empty: not measured)"
        )
        import_button.clicked.connect(self._ask_import)
        self.status = QtWidgets.QLabel("Type manual values, or import a CSV.")
        self.status.setWordWrap(True)
        self.plots = {trait: self._scatter_plot(trait) for trait in TRAITS}
        plots = QtWidgets.QHBoxLayout()
        for plot in self.plots.values():
            plots.addWidget(plot)
        layout = QtWidgets.QVBoxLayout(self)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(import_button)
        top.addStretch(1)
        layout.addLayout(top)
        layout.addWidget(self.table, 2)
        layout.addWidget(self.status)
        layout.addLayout(plots, 3)

    def set_plants(self, plants: list[PlantRecord]) -> None:
        """A new set of plants: their rows, manual cells kept for plants already listed."""
        before = {r.plant: r for r in self._records_quietly()}
        self.plants = list(plants)
        self.table.blockSignals(True)
        self.table.setRowCount(len(plants))
        for row, plant in enumerate(plants):
            old = before.get(plant.plant)
            cells = [
                str(plant.plant),
                f"{plant.height_cm:.1f}",
                _text(old.height_cm if old else None),
                f"{plant.width_cm:.1f}",
                _text(old.width_cm if old else None),
            ]
            for column, text in enumerate(cells):
                item = QtWidgets.QTableWidgetItem(text)
                if column not in MANUAL_COLUMN.values():
                    item.setFlags(item.flags() & ~QtCore.Qt.ItemFlag.ItemIsEditable)
                self.table.setItem(row, column, item)
        self.table.blockSignals(False)
        self.recompute()

    def set_manual(self, records: list[ManualRecord]) -> None:
        """Fill the manual cells from ``records`` (by plant id)."""
        by_id = {r.plant: r for r in records}
        self.table.blockSignals(True)
        for row, plant in enumerate(self.plants):
            record = by_id.get(plant.plant)
            if record is not None:
                self._cell(row, 2).setText(_text(record.height_cm))
                self._cell(row, 4).setText(_text(record.width_cm))
        self.table.blockSignals(False)
        unknown = sorted(set(by_id) - {p.plant for p in self.plants})
        self.recompute()
        if unknown:
            self.status.setText(
                self.status.text() + f"\nno such plant in this plot: {', '.join(map(str, unknown))}"
            )

    def import_csv(self, path: Path) -> None:
        """Read ``plant,height_cm,width_cm`` from ``path``; a bad file raises FieldappError."""
        self.set_manual(read_manual_csv(path))

    def records(self) -> list[ManualRecord]:
        """The manual values typed in; raises FieldappError naming the bad cell."""
        records = []
        for row, plant in enumerate(self.plants):
            where = f"plant {plant.plant}"
            height = parse_length(self._cell(row, 2).text(), f"{where}, manual height")
            width = parse_length(self._cell(row, 4).text(), f"{where}, manual width")
            if height is not None or width is not None:
                records.append(ManualRecord(plant.plant, height, width))
        return records

    def recompute(self) -> None:
        """Agreement over the plants with a manual value; the figures and plots follow."""
        try:
            records = self.records()
        except FieldappError as error:
            self.status.setText(f"⚠ {error}")
            return
        self.evaluation = (
            evaluate_traits(pair_with_manual(self.plants, records)) if records else None
        )
        self._show()
        self.evaluated.emit(self.evaluation)

    def _show(self) -> None:
        if self.evaluation is None:
            self.status.setText("No manual values yet: type them in the table, or import a CSV.")
            for plot in self.plots.values():
                plot.clear()
            return
        self.status.setText(
            "\n".join(summary_text(t, a) for t, a in self.evaluation.by_trait.items())
        )
        for trait, plot in self.plots.items():
            algorithm, manual = self.evaluation.values(trait)
            plot.clear()
            values = [*algorithm, *manual] or [0.0, 1.0]
            low, high = min(values) * 0.95, max(values) * 1.05
            plot.plot([low, high], [low, high], pen=pg.mkPen("k", width=1))
            plot.plot(
                manual,
                algorithm,
                pen=None,
                symbol="o",
                symbolSize=7,
                symbolBrush=(40, 160, 60),
                symbolPen="k",
            )

    def _records_quietly(self) -> list[ManualRecord]:
        try:
            return self.records()
        except FieldappError:
            return []

    def _cell(self, row: int, column: int) -> QtWidgets.QTableWidgetItem:
        """The table's item at ``row``, ``column`` of a plant listed: :meth:`set_plants` gives
        every cell of each plant's row one, and the rows change only there."""
        item = self.table.item(row, column)
        assert item is not None, f"no item at row {row}, column {column}"
        return item

    def _changed(self, item: QtWidgets.QTableWidgetItem) -> None:
        if item.column() in MANUAL_COLUMN.values():
            self.recompute()

    def _ask_import(self) -> None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Manual measurements", "", "CSV (*.csv)"
        )
        if name:
            try:
                self.import_csv(Path(name))
            except FieldappError as error:
                self.status.setText(f"⚠ {error}")

    @staticmethod
    def _scatter_plot(trait: str) -> pg.PlotWidget:
        plot = pg.PlotWidget(background="w")
        plot.setLabel("bottom", f"manual {trait} (cm)")
        plot.setLabel("left", f"algorithm {trait} (cm)")
        plot.setAspectLocked(True)
        plot.showGrid(x=True, y=True, alpha=0.3)
        return plot


def _text(value: float | None) -> str:
    return "" if value is None else f"{value:g}"
