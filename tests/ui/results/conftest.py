"""Small simulated sessions; every test under the GUI tests' leak check."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldapp.cli import main


@pytest.fixture(scope="session")
def plot_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("results") / "plot"
    assert main(["simulate", "--out", str(folder), "--stations", "4,5", "--views", "0-3"]) == 0
    return folder


@pytest.fixture(scope="session")
def plots(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two labelled seedling plots for the corrections: ``apart`` (plants 1 and 2) and
    ``merged`` (both seedlings as plant 1); copy one before changing it."""
    from ...fieldapp.results.seedlings import apart_and_merged

    return apart_and_merged(tmp_path_factory.mktemp("correction-ui"))


@pytest.fixture
def panel(qtbot, tmp_path):
    """A results panel with its own results database, shut down and released after the test."""
    from fieldapp.settings import Settings
    from ui.results import ResultsPanel

    settings = Settings()
    settings.paths.results_db = tmp_path / "results.sqlite"
    widget = ResultsPanel(settings)
    qtbot.addWidget(widget)
    yield widget
    widget.shutdown()
    release_plot_menus(widget)


def release_plot_menus(widget) -> None:
    """pyqtgraph's context menus are parentless: pytest still holds the panel while the leak
    check runs, so they are deleted here rather than with the panel."""
    import pyqtgraph as pg

    for plot in widget.findChildren(pg.PlotWidget):
        item = plot.getPlotItem()
        for menu in (item.vb.menu, item.ctrlMenu):
            if menu is not None:
                menu.deleteLater()


@pytest.fixture(autouse=True)
def _leak_check(no_leaks: None) -> None:
    """Every test here runs under the GUI tests' leak check (``tests/ui/conftest.py``): no
    thread left running, no top-level widget left alive."""
