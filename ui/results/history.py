"""History: the same plot's results over the season from the results database, and each
plant's growth curve (height and width against the date)."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import pyqtgraph as pg
from PySide6 import QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.results.db import Observation, ResultsDB
from fieldapp.results.history import growth_series

ALL = "all plants"


class HistoryPanel(QtWidgets.QWidget):
    """Growth curves of a plot from the results database at ``db_path``."""

    def __init__(self, db_path: Path, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.db_path = db_path
        self.observations: list[Observation] = []
        self.plot_name = QtWidgets.QLineEdit()
        self.plot_name.setPlaceholderText("plot name, e.g. north-field-A")
        self.record_button = QtWidgets.QPushButton("Record this run")
        self.record_button.setToolTip("add the reconstruction shown to the results database")
        self.load_button = QtWidgets.QPushButton("Show history")
        self.load_button.clicked.connect(self._load_clicked)
        self.trait = QtWidgets.QComboBox()
        self.trait.addItems(["height", "width"])
        self.trait.currentTextChanged.connect(self._draw)
        self.plant = QtWidgets.QComboBox()
        self.plant.currentTextChanged.connect(self._draw)
        self.status = QtWidgets.QLabel(f"Results database: {db_path}")
        self.status.setWordWrap(True)
        self.graph = pg.PlotWidget(background="w", axisItems={"bottom": pg.DateAxisItem()})
        self.graph.addLegend(offset=(5, 5))
        self.graph.showGrid(x=True, y=True, alpha=0.3)
        self.graph.setLabel("bottom", "date")
        top = QtWidgets.QHBoxLayout()
        for widget in (
            QtWidgets.QLabel("Plot"),
            self.plot_name,
            self.record_button,
            self.load_button,
            self.trait,
            self.plant,
        ):
            top.addWidget(widget)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.status)
        layout.addWidget(self.graph, 1)

    def record(self, plot: str, session_dir: Path | None, results_dir: Path) -> int:
        """Record a finished run of ``plot`` in the database; returns the run id."""
        with ResultsDB.open(self.db_path) as db:
            run_id = db.record_run(plot, session_dir, results_dir)
        self.status.setText(f"run {run_id} of plot {plot} recorded in {self.db_path}")
        return run_id

    def load(self, plot: str) -> list[Observation]:
        """The plot's observations by date; the curves are drawn."""
        if not self.db_path.exists():
            raise FieldappError(f"{self.db_path}: no results database yet (record a run first)")
        with ResultsDB.open(self.db_path, create=False) as db:
            self.observations = db.history(plot)
        dates = sorted({o.date for o in self.observations})
        plants = sorted({o.plant_number for o in self.observations})
        self.plant.blockSignals(True)
        self.plant.clear()
        self.plant.addItems([ALL, *map(str, plants)])
        self.plant.blockSignals(False)
        self.status.setText(
            f"plot {plot}: {len(plants)} plants on {len(dates)} dates "
            + (f"({dates[0]} to {dates[-1]})" if dates else "")
        )
        self._draw()
        return self.observations

    def series(self) -> dict[int, list[tuple[dt.date, float]]]:
        """The curves drawn: per plant, (date, value in cm) of the chosen trait."""
        series = growth_series(self.observations, self.trait.currentText())
        chosen = self.plant.currentText()
        if chosen and chosen != ALL:
            series = {p: s for p, s in series.items() if p == int(chosen)}
        return series

    def _draw(self) -> None:
        self.graph.clear()
        self.graph.setLabel("left", f"{self.trait.currentText()} (cm)")
        for index, (plant, points) in enumerate(sorted(self.series().items())):
            stamps = [_timestamp(d) for d, _ in points]
            self.graph.plot(
                stamps,
                [v for _, v in points],
                name=str(plant),
                symbol="o",
                symbolSize=5,
                pen=pg.intColor(index, hues=12),
            )

    def _load_clicked(self) -> None:
        try:
            self.load(self.plot_name.text().strip())
        except FieldappError as error:
            self.status.setText(f"⚠ {error}")


def _timestamp(date: dt.date) -> float:
    return dt.datetime(date.year, date.month, date.day, 12, tzinfo=dt.UTC).timestamp()
