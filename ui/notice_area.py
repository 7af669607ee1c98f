"""The notification strip and the notice log.

The strip (:class:`NotificationPanel`) has a fixed height and is always laid out, empty or
not, so a notice never moves the page or a button under the mouse. It shows one notice at a
time: the newest open error (errors stay until dismissed), else the newest news, which
expires after :data:`ui.notifications.LIFETIME_S` on the panel's ``clock`` (injectable;
a QTimer calls :meth:`NotificationPanel.expire`). "+N more" opens the log
(:class:`NoticeLog`), which keeps every notice of the session, newest first.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from PySide6 import QtCore, QtWidgets

from ui.notifications import LIFETIME_S, STYLE, Level, Notice, Notifier, rich_text, stamp

EXPIRY_TICK_MS = 1000
SHOWN_CHARS = 180
"""Longer messages are cut in the strip (with "…"); its tooltip and the log have them whole."""
EMPTY_TEXT = "<span style='color:#78909c'>No open notices.</span>"


class NoticeCard(QtWidgets.QFrame):
    """The notice shown in the strip: level, title, message and advice; a dismiss button."""

    dismissed = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.notice: Notice | None = None
        self.setObjectName("noticeCard")
        self.label = QtWidgets.QLabel(EMPTY_TEXT)
        self.label.setWordWrap(True)
        self.label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.label.setAlignment(QtCore.Qt.AlignmentFlag.AlignVCenter)
        self.close_button = QtWidgets.QToolButton()
        self.close_button.setText("✕")
        self.close_button.setToolTip("Dismiss this notice (the log keeps it)")
        self.close_button.setAutoRaise(True)
        self.close_button.clicked.connect(self.dismissed)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(8, 2, 4, 2)
        layout.addWidget(self.label, 1)
        layout.addWidget(self.close_button, 0, QtCore.Qt.AlignmentFlag.AlignTop)
        self.show_notice(None)

    def show_notice(self, notice: Notice | None) -> None:
        self.notice = notice
        style = STYLE[notice.level] if notice is not None else "border:1px solid transparent;"
        self.setStyleSheet(f"#noticeCard {{{style} border-radius:4px;}}")
        self.label.setText(rich_text(notice, SHOWN_CHARS) if notice is not None else EMPTY_TEXT)
        self.label.setToolTip(rich_text(notice) if notice is not None else "")
        # hidden but still laid out: the strip keeps its size either way
        self.close_button.setEnabled(notice is not None)
        self.close_button.setVisible(notice is not None)


class NotificationPanel(QtWidgets.QWidget):
    """The strip: one open notice, "+N more" and the log button, at a fixed height."""

    log_requested = QtCore.Signal()

    def __init__(
        self,
        notifier: Notifier,
        parent: QtWidgets.QWidget | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(parent)
        self.clock = clock
        self.open: list[tuple[Notice, float | None]] = []  # (notice, expiry on the clock)
        self.card = NoticeCard()
        self.card.dismissed.connect(self.dismiss)
        retain = self.card.close_button.sizePolicy()
        retain.setRetainSizeWhenHidden(True)
        self.card.close_button.setSizePolicy(retain)
        self.more = QtWidgets.QPushButton("Log")
        self.more.setToolTip("Every notice of this session, with its advice")
        self.more.setFixedWidth(96)
        self.more.clicked.connect(self.log_requested)
        row = QtWidgets.QHBoxLayout(self)
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(self.card, 1)
        row.addWidget(self.more, 0, QtCore.Qt.AlignmentFlag.AlignVCenter)
        lines = self.fontMetrics().lineSpacing()
        self.setFixedHeight(3 * lines + 10)  # the notice (up to two lines), what to do
        self.timer = QtCore.QTimer(self)
        self.timer.setInterval(EXPIRY_TICK_MS)
        self.timer.timeout.connect(self.expire)
        self.timer.start()
        notifier.posted.connect(self.show_notice)

    def cards(self) -> list[NoticeCard]:
        """The card when it shows a notice (none when the strip is empty)."""
        return [self.card] if self.card.notice is not None else []

    def shown(self) -> Notice | None:
        """The newest open error, else the newest open notice."""
        errors = [n for n, _ in self.open if n.level is Level.ERROR]
        if errors:
            return errors[-1]
        return self.open[-1][0] if self.open else None

    @QtCore.Slot(object)
    def show_notice(self, notice: Notice) -> None:
        if notice.topic:  # the newer word on a topic replaces the open one
            self.open = [(n, t) for n, t in self.open if n.topic != notice.topic]
        lifetime = LIFETIME_S[notice.level]
        self.open.append((notice, None if lifetime is None else self.clock() + lifetime))
        self._refresh()

    @QtCore.Slot()
    def expire(self) -> None:
        """Drop the news whose time is up (errors stay)."""
        now = self.clock()
        kept = [(n, t) for n, t in self.open if t is None or t > now]
        if len(kept) != len(self.open):
            self.open = kept
            self._refresh()

    @QtCore.Slot()
    def dismiss(self) -> None:
        """Close the notice shown (the log keeps it)."""
        shown = self.shown()
        self.open = [(n, t) for n, t in self.open if n is not shown]
        self._refresh()

    def clear(self) -> None:
        self.open = []
        self._refresh()

    def _refresh(self) -> None:
        self.card.show_notice(self.shown())
        more = len(self.open) - 1
        self.more.setText(f"+{more} · Log" if more > 0 else "Log")


class NoticeLog(QtWidgets.QTreeWidget):
    """Every notice of the session, newest first: time, level, what happened, what to do."""

    def __init__(self, notifier: Notifier, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setHeaderLabels(["Time", "Level", "What happened", "What to do"])
        self.setRootIsDecorated(False)
        self.setWordWrap(True)
        self.setAlternatingRowColors(True)
        for notice in notifier.history:
            self.add(notice)
        notifier.posted.connect(self.add)
        self.setColumnWidth(0, 70)
        self.setColumnWidth(1, 70)
        self.setColumnWidth(2, 560)

    @QtCore.Slot(object)
    def add(self, notice: Notice) -> None:
        row = [stamp(notice), notice.level.value, notice.text(), notice.advice]
        item = QtWidgets.QTreeWidgetItem(row)
        for column, text in enumerate(row):
            item.setToolTip(column, text)
        self.insertTopLevelItem(0, item)

    def texts(self) -> list[str]:
        """What happened, newest first."""
        items = (self.topLevelItem(i) for i in range(self.topLevelItemCount()))
        return [item.text(2) for item in items if item is not None]
