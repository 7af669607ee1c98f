"""Growth charts read well for one date and for many: whole dates on the axis (never times
of day), one date as a strip of points on a week-wide axis (not years), a point per plant,
the legend outside the data, "1 date" not "1 dates"; both in the exported figure
(matplotlib objects) and in the History panel (pyqtgraph)."""

from __future__ import annotations

import datetime as dt
import re
from pathlib import Path

import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from pytestqt.qtbot import QtBot

from fieldapp.evaluate.figures import growth_figure, growth_png
from fieldapp.results.db import Observation
from ui.results.history import HistoryPanel

DAY = dt.date(2026, 5, 14)
ISO = re.compile(r"^\d{4}-\d{2}-\d{2}$")


def one_date(plants: int) -> dict[int, list[tuple[dt.date, float]]]:
    return {p: [(DAY, 10.0 + p)] for p in range(1, plants + 1)}


def many_dates(plants: int, days: list[int]) -> dict[int, list[tuple[dt.date, float]]]:
    return {
        p: [(DAY + dt.timedelta(days=d), 5.0 + p + d) for d in days] for p in range(1, plants + 1)
    }


def drawn_labels(figure) -> list[str]:  # type: ignore[no-untyped-def]
    FigureCanvasAgg(figure).draw()
    return [t.get_text() for t in figure.axes[0].get_xticklabels() if t.get_text()]


def legend_outside(figure) -> bool:  # type: ignore[no-untyped-def]
    axes = figure.axes[0]
    renderer = FigureCanvasAgg(figure).get_renderer()
    legend = axes.get_legend().get_window_extent(renderer)
    return legend.x0 >= axes.get_window_extent(renderer).x1


@pytest.mark.parametrize("plants", [1, 3, 16])
def test_one_date_is_a_strip_of_points_on_a_week(plants: int) -> None:
    figure = growth_figure("height", one_date(plants), "plot A")
    axes = figure.axes[0]
    low, high = axes.get_xlim()
    assert high - low == pytest.approx(6.0)  # a week, not 2025-2029
    assert low < DAY.toordinal() < high
    assert drawn_labels(figure) == [DAY.isoformat()]
    lines = axes.get_lines()
    assert len(lines) == plants and all(line.get_linestyle() == "None" for line in lines)
    xs = [float(line.get_xdata()[0]) for line in lines]
    assert len(set(xs)) == plants and all(abs(x - DAY.toordinal()) <= 0.3 + 1e-6 for x in xs)
    noun = "plant" if plants == 1 else "plants"
    assert axes.get_title().endswith(f"({plants} {noun} on 1 date)")
    assert legend_outside(figure)


@pytest.mark.parametrize("days", [[0, 7], [0, 3, 10, 24], list(range(0, 120, 6))])
def test_many_dates_have_date_labels_and_lines(days: list[int]) -> None:
    figure = growth_figure("width", many_dates(4, days), "plot A")
    axes = figure.axes[0]
    labels = drawn_labels(figure)
    assert labels and all(ISO.match(label) for label in labels), labels
    assert 2 <= len(labels) <= 9
    low, high = axes.get_xlim()
    assert low < DAY.toordinal() and high > (DAY + dt.timedelta(days=days[-1])).toordinal()
    assert high - low < days[-1] * 1.3 + 3
    assert all(line.get_linestyle() == "-" for line in axes.get_lines())
    assert axes.get_title().endswith(f"(4 plants on {len(days)} dates)")
    assert legend_outside(figure)


def test_the_png_is_drawn() -> None:
    assert growth_png("height", one_date(2), "plot A").startswith(b"\x89PNG")


def observations(days: list[int], plants: int) -> list[Observation]:
    return [
        Observation(p, p, DAY + dt.timedelta(days=d), f"s{d}", d, 0.0, 0.0, 10.0 + p, 5.0)
        for d in days
        for p in range(1, plants + 1)
    ]


def test_history_of_one_date(qtbot: QtBot, tmp_path: Path) -> None:
    panel = HistoryPanel(tmp_path / "results.sqlite")
    qtbot.addWidget(panel)
    panel.resize(900, 500)
    panel.show_observations("plot-A", observations([0], 16))
    assert "16 plants on 1 date (2026-05-14)" in panel.status.text()
    (low, high), _ = panel.graph.getPlotItem().getViewBox().viewRange()
    assert low < DAY.toordinal() < high and high - low == pytest.approx(6.0)
    axis = panel.graph.getPlotItem().getAxis("bottom")
    ticks = [v for _, values in axis.tickValues(low, high, 800) for v in values]
    assert DAY.toordinal() in ticks and all(float(v).is_integer() for v in ticks)
    assert axis.tickStrings([DAY.toordinal()], 1.0, 1.0) == ["2026-05-14"]
    items = panel.graph.getPlotItem().listDataItems()
    assert len(items) == 16
    assert len({float(item.getData()[0][0]) for item in items}) == 16  # a point per plant
    assert len(panel.legend.items) == 16


def test_history_of_many_dates_keeps_the_legend_outside(qtbot: QtBot, tmp_path: Path) -> None:
    panel = HistoryPanel(tmp_path / "results.sqlite")
    qtbot.addWidget(panel)
    panel.resize(900, 500)
    panel.show()
    qtbot.waitExposed(panel)
    panel.show_observations("plot-A", observations([0, 9, 30], 3))
    assert "3 plants on 3 dates (2026-05-14 to 2026-06-13)" in panel.status.text()
    (low, high), _ = panel.graph.getPlotItem().getViewBox().viewRange()
    assert low < DAY.toordinal() and high > DAY.toordinal() + 30
    view = panel.graph.getPlotItem().getViewBox().sceneBoundingRect()
    legend = panel.legend.sceneBoundingRect()
    assert legend.left() >= view.right() - 1.0, (legend, view)
