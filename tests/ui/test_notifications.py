"""The notification strip never moves the page; news expires (on a fake clock), errors stay
until dismissed, the log keeps everything; a newer notice on a topic replaces the stale one;
no title said twice."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from PySide6 import QtCore, QtWidgets
from pytestqt.qtbot import QtBot

from ui.main_window import MainWindow
from ui.notice_area import NoticeLog, NotificationPanel
from ui.notifications import LIFETIME_S, Level, Notice, Notifier

LONG_ADVICE = "Check the thing, then the other thing, then press the button again. " * 4


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 1000.0

    def __call__(self) -> float:
        return self.now_s


@pytest.fixture
def panel(qtbot: QtBot) -> tuple[Notifier, NotificationPanel, FakeClock]:
    notifier = Notifier()
    clock = FakeClock()
    panel = NotificationPanel(notifier, clock=clock)
    qtbot.addWidget(panel)
    notifier.setParent(panel)
    return notifier, panel, clock


def shown_title(panel: NotificationPanel) -> str | None:
    notice = panel.shown()
    return None if notice is None else notice.title


def test_news_expires_and_errors_stay_until_dismissed(
    panel: tuple[Notifier, NotificationPanel, FakeClock],
) -> None:
    notifier, strip, clock = panel
    notifier.error("Camera", RuntimeError("gone"))
    notifier.info("Saved", "frame saved")
    notifier.warn("Table lost", "no answer", "Check its cable")
    assert shown_title(strip) == "Camera"  # an open error comes first
    assert strip.more.text() == "+2 · Log"
    strip.dismiss()
    assert shown_title(strip) == "Table lost"
    clock.now_s += LIFETIME_S[Level.INFO] + 0.1  # type: ignore[operator]
    strip.timer.timeout.emit()  # what the QTimer does each tick
    assert [n.title for n, _ in strip.open] == ["Table lost"]
    clock.now_s += LIFETIME_S[Level.WARNING]  # type: ignore[operator]
    strip.expire()
    assert strip.open == [] and strip.cards() == []
    notifier.error("Base", RuntimeError("offline"))
    clock.now_s += 1e6
    strip.expire()
    assert shown_title(strip) == "Base"  # an error never expires
    strip.card.close_button.click()
    assert strip.shown() is None
    assert strip.timer.isActive()


def test_a_newer_notice_on_a_topic_replaces_the_stale_one(
    panel: tuple[Notifier, NotificationPanel, FakeClock],
) -> None:
    notifier, strip, _clock = panel
    notifier.error("Mission not started", RuntimeError("no camera"), topic="mission")
    notifier.error("Camera", RuntimeError("unplugged"))
    notifier.post(Notice(Level.INFO, "Mission complete", "16 captures taken", topic="mission"))
    titles = [n.title for n, _ in strip.open]
    assert titles == ["Camera", "Mission complete"]  # the unrelated error stays


def test_the_title_is_not_said_twice(panel: tuple[Notifier, NotificationPanel, FakeClock]) -> None:
    notifier, strip, _clock = panel
    notifier.post(Notice(Level.INFO, "Mission complete", "mission complete: 16 captures taken"))
    notice = notifier.history[-1]
    assert notice.message == "16 captures taken"
    assert notice.text() == "Mission complete: 16 captures taken"
    assert strip.card.label.text().lower().count("mission complete") == 1


def test_the_log_keeps_every_notice_newest_first(
    panel: tuple[Notifier, NotificationPanel, FakeClock], qtbot: QtBot
) -> None:
    notifier, strip, clock = panel
    notifier.info("before", "posted before the log was made")
    log = NoticeLog(notifier)
    qtbot.addWidget(log)
    for n in range(5):
        notifier.warn(f"warning {n}", "text", "advice")
    clock.now_s += 1e6
    strip.expire()
    assert strip.open == []
    assert log.texts() == [f"warning {n}: text" for n in reversed(range(5))] + [
        "before: posted before the log was made"
    ]


def test_notices_never_move_the_page(make_window: Callable[..., MainWindow], qtbot: QtBot) -> None:
    window = make_window()
    window.show()
    qtbot.waitExposed(window)
    page, stop = window.stack, window.stop_button

    def places() -> tuple[QtCore.QRect, QtCore.QPoint]:
        QtWidgets.QApplication.processEvents()
        return page.geometry(), stop.mapTo(window, QtCore.QPoint(0, 0))

    before = places()
    notifier = window.context.notifier
    for n in range(6):
        notifier.warn(f"warning {n}", "a long message " * 12, LONG_ADVICE)
        assert places() == before
    notifier.error("Camera", RuntimeError("unplugged " * 30))
    assert places() == before
    window.notices.dismiss()
    window.notices.clock = lambda: 1e12
    window.notices.expire()
    assert window.notices.cards() == []
    assert places() == before
    assert len(window.log.texts()) == 7


def test_the_log_opens_from_the_strip(make_window: Callable[..., MainWindow], qtbot: QtBot) -> None:
    window = make_window()
    window.show()
    qtbot.waitExposed(window)
    assert not window.log_dock.isVisible()
    window.context.notifier.info("one", "x")
    window.context.notifier.info("two", "y")
    assert window.notices.more.text() == "+1 · Log"
    window.notices.more.click()
    assert window.log_dock.isVisible()
    assert window.log.texts() == ["two: y", "one: x"]
    menus = [action.text() for action in window.menuBar().actions()]
    assert menus == ["&View", "&Help"]
    assert "fieldapp" in window.about_text()
