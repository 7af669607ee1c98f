"""How the main window hosts its pages: a list of :class:`PageSpec` (key, title, factory).

The Calibrate and Results pages belong to the workstation GUI (``ui.calibration``,
``ui.results``). :func:`default_pages` uses their widgets as soon as those packages provide a
``create_page(context) -> QWidget`` function (or, for Results, ``ResultsPanel(settings)``);
until then it shows the small pages of :mod:`ui.fallback_pages`, which offer what the core can
already do. A finished mission's session folder is handed to the Results page's
``open_session(folder)`` when it has one. A page may also define
``confirm_close(parent) -> bool`` (asked before the window closes) and ``shutdown()``
(called once it closes); the main window calls both when present.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from PySide6 import QtWidgets

if TYPE_CHECKING:
    from ui.context import AppContext

log = logging.getLogger(__name__)

PageFactory = Callable[["AppContext"], QtWidgets.QWidget]


@dataclass(frozen=True)
class PageSpec:
    """One page of the side bar: ``key`` (stable, remembered), ``title``, ``factory``."""

    key: str
    title: str
    factory: PageFactory
    tooltip: str = ""


def external_page(module_name: str) -> PageFactory | None:
    """``module_name.create_page`` when that package exists and provides it, else ``None``."""
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        if error.name is not None and module_name.startswith(error.name):
            return None
        raise
    factory = getattr(module, "create_page", None)
    return factory if callable(factory) else None


def _mission(context: AppContext) -> QtWidgets.QWidget:
    from ui.mission.page import MissionPage

    return MissionPage(context)


def _live(context: AppContext) -> QtWidgets.QWidget:
    from ui.live.preview import LivePreview

    return LivePreview(context)


def _calibrate_fallback(context: AppContext) -> QtWidgets.QWidget:
    from ui.fallback_pages import CalibrationSummaryPage

    return CalibrationSummaryPage(context)


def _results_fallback(context: AppContext) -> QtWidgets.QWidget:
    from ui.fallback_pages import SessionsPage

    return SessionsPage(context)


def _results_panel() -> PageFactory | None:
    """The workstation GUI's ``ui.results.ResultsPanel(settings)``, its ``error(str)`` signal
    sent to the notification area."""
    try:
        from ui.results import ResultsPanel
    except ImportError:
        return None

    def make(context: AppContext) -> QtWidgets.QWidget:
        panel: QtWidgets.QWidget = ResultsPanel(context.settings)
        error = getattr(panel, "error", None)
        if error is not None:
            error.connect(lambda text: context.notifier.warn("Results", str(text)))
        return panel

    return make


def default_pages() -> list[PageSpec]:
    """Calibrate, Mission, Live, Results, in the order of a field day."""
    calibrate = external_page("ui.calibration") or _calibrate_fallback
    results = external_page("ui.results") or _results_panel() or _results_fallback
    return [
        PageSpec("calibrate", "Calibrate", calibrate, "intrinsics, view step, stations"),
        PageSpec("mission", "Mission", _mission, "plan, run and watch a mission"),
        PageSpec("live", "Live", _live, "the camera's live depth, colour, IR and 3D"),
        PageSpec("results", "Results", results, "sessions, reconstruction, traits"),
    ]
