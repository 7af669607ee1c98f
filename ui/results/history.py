"""History: the same plot's results over the season from the results database, and each
plant's growth curve (height and width against the date).

The date axis counts days (proleptic ordinals) and labels whole days only (``2026-05-14``),
never times of day; one date is shown as a strip of points per plant on a week-wide axis;
the legend sits in its own column right of the data."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6 import QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.results.db import Observation, ResultsDB
from fieldapp.results.history import growth_series

ALL = "all plants"
ONE_DATE_MARGIN_D = 3.0
SPREAD_D = 0.3  # half-width of one date's strip of plants, in days
LEGEND_WIDTH_PX = 90


class DayAxis(pg.AxisItem):  # type: ignore[misc]  # pyqtgraph is untyped
    """An axis of day ordinals labelled with whole dates."""

    def tickValues(
        self, minVal: float, maxVal: float, size: float
    ) -> list[tuple[float, list[float]]]:
        span_d = max(1.0, maxVal - minVal)
        step_d = max(1, int(np.ceil(span_d / max(1.0, size / 90.0))))
        first = int(np.ceil(minVal / step_d) * step_d)
        return [(float(step_d), [float(d) for d in range(first, int(maxVal) + 1, step_d)])]

    def tickStrings(self, values: list[float], scale: float, spacing: float) -> list[str]:
        return [dt.date.fromordinal(round(v)).isoformat() for v in values]


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
        self.graph = pg.PlotWidget(background="w", axisItems={"bottom": DayAxis("bottom")})
        self.graph.showGrid(x=True, y=True, alpha=0.3)
        self.graph.setLabel("bottom", "date")
        self.legend = self._outside_legend()
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
        """Record a finished run of ``plot`` in the database and show the plot's history with
        it; returns the run id. The status line confirms it in green."""
        with ResultsDB.open(self.db_path) as db:
            run_id = db.record_run(plot, session_dir, results_dir)
        self.load(plot)
        self.status.setText(
            f"<b style='color:#2e7d32'>✓ Recorded</b> run {run_id} of plot {plot} in "
            f"{self.db_path}. {self.status.text()}"
        )
        return run_id

    def load(self, plot: str) -> list[Observation]:
        """The plot's observations by date; the curves are drawn."""
        if not self.db_path.exists():
            raise FieldappError(f"{self.db_path}: no results database yet (record a run first)")
        with ResultsDB.open(self.db_path, create=False) as db:
            observations = db.history(plot)
        self.show_observations(plot, observations)
        return observations

    def show_observations(self, plot: str, observations: list[Observation]) -> None:
        """Draw ``observations`` of ``plot`` and say how many plants and dates they hold."""
        self.observations = observations
        dates = sorted({o.date for o in observations})
        plants = sorted({o.plant_number for o in observations})
        self.plant.blockSignals(True)
        self.plant.clear()
        self.plant.addItems([ALL, *map(str, plants)])
        self.plant.blockSignals(False)
        when = "no date"
        if dates:
            span = f"{dates[0]}" if len(dates) == 1 else f"{dates[0]} to {dates[-1]}"
            when = f"{counted(len(dates), 'date')} ({span})"
        self.status.setText(f"plot {plot}: {counted(len(plants), 'plant')} on {when}")
        self._draw()

    def series(self) -> dict[int, list[tuple[dt.date, float]]]:
        """The curves drawn: per plant, (date, value in cm) of the chosen trait."""
        series = growth_series(self.observations, self.trait.currentText())
        chosen = self.plant.currentText()
        if chosen and chosen != ALL:
            series = {p: s for p, s in series.items() if p == int(chosen)}
        return series

    def _outside_legend(self) -> pg.LegendItem:
        """A legend in an empty right-hand axis column, so it never covers a point."""
        item = self.graph.getPlotItem()
        item.showAxis("right")
        right = item.getAxis("right")
        right.setWidth(LEGEND_WIDTH_PX)
        right.setStyle(showValues=False, tickLength=0)
        right.setPen(pg.mkPen(None))
        legend = pg.LegendItem(offset=None)
        legend.setParentItem(item)
        legend.anchor(itemPos=(1, 0), parentPos=(1, 0), offset=(-4, 4))
        return legend

    def _draw(self) -> None:
        self.graph.clear()
        self.legend.clear()
        self.graph.setLabel("left", f"{self.trait.currentText()} (cm)")
        series = sorted(self.series().items())
        days = sorted({d.toordinal() for _, points in series for d, _ in points})
        for index, (plant, points) in enumerate(series):
            x = np.array([d.toordinal() for d, _ in points], dtype=np.float64)
            if len(days) == 1 and len(series) > 1:  # one date: a strip, one point per plant
                x += SPREAD_D * (2.0 * index / (len(series) - 1) - 1.0)
            color = pg.intColor(index, hues=12)
            curve = self.graph.plot(
                x, [v for _, v in points], symbol="o", symbolSize=7, symbolBrush=color,
                pen=color if len(points) > 1 else None,
            )  # fmt: skip
            self.legend.addItem(curve, str(plant))
        if days:
            margin = (
                ONE_DATE_MARGIN_D if days[0] == days[-1] else max(1.0, 0.05 * (days[-1] - days[0]))
            )
            self.graph.setXRange(days[0] - margin, days[-1] + margin, padding=0)

    def _load_clicked(self) -> None:
        try:
            self.load(self.plot_name.text().strip())
        except FieldappError as error:
            self.status.setText(f"⚠ {error}")


def counted(count: int, noun: str) -> str:
    """``1 date``, ``2 dates``."""
    return f"{count} {noun}" if count == 1 else f"{count} {noun}s"
