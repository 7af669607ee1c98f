"""How the main window hosts its pages: a list of :class:`PageSpec` (key, title, factory).

:func:`default_pages` gives the four pages of a field day: Calibrate (:mod:`ui.calibration`),
Mission (:mod:`ui.mission`), Live (:mod:`ui.live`) and Results (:mod:`ui.results`). Each
factory imports its page when the page is first built, so start-up pays only for what is
shown. A finished mission's session folder is handed to the Results page's
``open_session(folder)``. A page may also define ``confirm_close(parent) -> bool`` (asked
before the window closes) and ``shutdown()`` (called once it closes); the main window calls
both when present.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from PySide6 import QtWidgets

if TYPE_CHECKING:
    from ui.context import AppContext

PageFactory = Callable[["AppContext"], QtWidgets.QWidget]


@dataclass(frozen=True)
class PageSpec:
    """One page of the side bar: ``key`` (stable, remembered), ``title``, ``factory``."""

    key: str
    title: str
    factory: PageFactory
    tooltip: str = ""


def _calibrate(context: AppContext) -> QtWidgets.QWidget:
    from ui.calibration import create_page

    return create_page(context)


def _mission(context: AppContext) -> QtWidgets.QWidget:
    from ui.mission.page import MissionPage

    return MissionPage(context)


def _live(context: AppContext) -> QtWidgets.QWidget:
    from ui.live.preview import LivePreview

    return LivePreview(context)


def _results(context: AppContext) -> QtWidgets.QWidget:
    """The results panel, its ``error(str)`` signal sent to the notification area."""
    from ui.results import ResultsPanel

    panel = ResultsPanel(context.settings)
    panel.error.connect(lambda text: context.notifier.warn("Results", str(text)))
    return panel


def default_pages() -> list[PageSpec]:
    """Calibrate, Mission, Live, Results, in the order of a field day."""
    return [
        PageSpec("calibrate", "Calibrate", _calibrate, "intrinsics, view step, stations"),
        PageSpec("mission", "Mission", _mission, "plan, run and watch a mission"),
        PageSpec("live", "Live", _live, "the camera's live depth, colour, IR and 3D"),
        PageSpec("results", "Results", _results, "sessions, reconstruction, traits"),
    ]
