"""The mission page's follow-ups from issue 25: the thumbnail grid follows the station being
captured, a double-clicked thumbnail shows its depth and colour large, the elapsed time keeps
counting while paused (on a fake clock) and says "paused", and the Set-up tab asks before the
base drives."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from PySide6 import QtCore
from pytestqt.qtbot import QtBot

from devices.camera.quality import QualityReport
from fieldapp.io.session import load_session
from fieldapp.mission.events import MissionProgress, StationReached, ViewCaptured
from ui.main_window import MainWindow
from ui.mission.depth_view import DepthViewer, read_view_depth
from ui.mission.progress import ProgressPanel, format_duration

from .test_mission import small_plan


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 50.0

    def __call__(self) -> float:
        return self.now_s


def captured(station: int, view: int) -> ViewCaptured:
    quality = QualityReport(0.95, 0.6, 0.01, 0.0, 0.0, 0.05)
    thumbnail = np.zeros((53, 64, 3), np.uint8)
    return ViewCaptured(station, view, 45.0 * view, quality, True, thumbnail, 1)


def test_the_grid_follows_the_station_being_captured(qtbot: QtBot) -> None:
    panel = ProgressPanel()
    qtbot.addWidget(panel)
    panel.show_plan(small_plan())
    panel.add_station(StationReached(6, 3.2, 1.6, 0.0, 1))
    assert panel.grid.currentRow() == panel.rows[6] == 1
    panel.add_view(captured(6, 2))
    assert (panel.grid.currentRow(), panel.grid.currentColumn()) == (1, 2)
    panel.add_station(StationReached(3, 3.2, 0.0, 0.0, 1))
    assert panel.grid.currentRow() == 2


def test_elapsed_time_counts_while_paused(qtbot: QtBot) -> None:
    clock = FakeClock()
    panel = ProgressPanel(clock=clock)
    qtbot.addWidget(panel)
    panel.show_plan(small_plan())
    panel.set_progress(MissionProgress(3, 12, 60.0, 180.0, "station 5 view 2"))
    assert panel.times.text() == "elapsed 1 min 00 s · remaining 3 min 00 s"
    assert panel.ticker.isActive()
    clock.now_s += 125.0  # paused: no progress report for two minutes
    panel.ticker.timeout.emit()  # what the QTimer does each second
    assert panel.times.text() == f"elapsed {format_duration(185.0)} · remaining 3 min 00 s"
    panel.set_paused(True)  # the page's state says PAUSED: the times say so too
    assert panel.times.text() == f"elapsed {format_duration(185.0)} (paused) · remaining 3 min 00 s"
    clock.now_s += 60.0
    panel.tick()
    assert panel.times.text().startswith(f"elapsed {format_duration(245.0)} (paused)")
    panel.set_paused(False)
    assert "(paused)" not in panel.times.text()
    panel.finish("complete: 12 captured, 0 missing")
    clock.now_s += 10.0
    panel.tick()
    assert panel.times.text() == "complete: 12 captured, 0 missing"
    assert not panel.ticker.isActive()


def test_the_base_drives_only_after_the_operator_agrees(
    make_window: Callable[..., MainWindow],
    wait_until: Callable[..., bool],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    window = make_window()
    setup = window.pages["mission"].setup  # type: ignore[attr-defined]
    window.toggle_connection()
    assert wait_until(lambda: window.context.hub.connected)
    questions: list[str] = []
    answer = [False]

    def ask(_parent: object, title: str, text: str) -> bool:
        questions.append(f"{title} {text}")
        return answer[0]

    monkeypatch.setattr("ui.mission.setup_panel.ask", ask)
    setup.x_m.setValue(0.5)
    setup.goto_pose()
    assert len(questions) == 1 and "x 0.50 m" in questions[0]
    assert not setup.busy and setup.last_result == ""
    answer[0] = True
    setup.goto_pose()
    assert len(questions) == 2
    assert wait_until(lambda: setup.last_result.startswith("Base to pose"))


def test_a_double_clicked_thumbnail_shows_its_depth_large(
    make_window: Callable[..., MainWindow], wait_until: Callable[..., bool]
) -> None:
    window = make_window()
    page = window.pages["mission"]
    page.editor.set_plan(small_plan())  # type: ignore[attr-defined]
    window.toggle_connection()
    assert wait_until(lambda: window.context.hub.connected)
    page.start_button.click()  # type: ignore[attr-defined]
    assert wait_until(lambda: page.result is not None, 60.0)  # type: ignore[attr-defined]
    grid = page.progress.grid  # type: ignore[attr-defined]
    opened: list[tuple[int, int]] = []
    page.progress.view_opened.connect(lambda s, v: opened.append((s, v)))  # type: ignore[attr-defined]
    grid.cellDoubleClicked.emit(1, 2)  # station 6 (the plan's second), view 2
    assert opened == [(6, 2)]
    viewers = [w for w in page.findChildren(DepthViewer) if w.isVisible()]
    assert len(viewers) == 1 and "station 6, view 2" in viewers[0].windowTitle()
    session = load_session(page.controller.folder)  # type: ignore[attr-defined]
    capture = next(c for c in session.captures if (c.station, c.view) == (6, 2))
    images = session.read_capture(capture)
    expected = images.depth_m
    shown = read_view_depth(session.folder, 6, 2)
    box = viewers[0].panel.depth_plot.vb  # the whole image framed, not a corner of it
    assert wait_until(lambda: box.viewRect().contains(QtCore.QRectF(1, 1, 510, 422)))
    assert box.viewRect().width() < 2 * 512 and box.viewRect().height() < 2 * 424
    colour = viewers[0].panel.second_item.image  # the colour beside the depth
    assert viewers[0].panel.second_plot.isVisible() and np.array_equal(colour, images.color)
    assert np.array_equal(np.isnan(shown), np.isnan(expected))
    assert np.allclose(shown[~np.isnan(shown)], expected[~np.isnan(expected)])
    low, high = viewers[0].levels_m
    assert 0.0 < low < high < 10.0
    viewers[0].close()
    errors_before = len(window.context.notifier.history)
    assert page.open_view(6, 99) is None  # type: ignore[attr-defined]
    assert len(window.context.notifier.history) == errors_before + 1
    assert "not captured" in window.context.notifier.history[-1].message


def test_the_set_up_tab_parks_the_table_and_takes_the_operator_s_zero(
    make_window: Callable[..., MainWindow], wait_until: Callable[..., bool]
) -> None:
    """docs/TABLE.md: a controller reset by opening its port counts from where the table
    stands; the operator parks it at machine zero, or says it stands at its zero mark."""
    window = make_window()
    setup = window.pages["mission"].setup  # type: ignore[attr-defined]
    window.toggle_connection()
    assert wait_until(lambda: window.context.hub.connected)
    setup.angle.setValue(90.0)
    setup.turn_to()
    assert wait_until(lambda: setup.last_result.startswith("Table: at "))
    assert _degrees(setup.last_result) == pytest.approx(90.0, abs=0.2)
    setup.park_table()
    assert wait_until(lambda: setup.last_result.startswith("Table park: at "))
    assert _degrees(setup.last_result) == pytest.approx(0.0, abs=0.2)
    assert "machine zero" in setup.last_result
    setup.confirm_table_zero()
    assert wait_until(lambda: setup.last_result.startswith("Table zero: confirmed: Idle"))


def _degrees(result: str) -> float:
    """The angle in a set-up result such as ``Table: at 89.970 deg``."""
    return float(result.split(" at ", 1)[1].split(" deg", 1)[0])
