"""One notification sink for the whole window: errors and warnings with their advice.

Anything that goes wrong (a device that fails to connect, a mission that stops, a bad file)
is posted to the :class:`Notifier` as a :class:`Notice`; the :class:`NotificationPanel` shows
the newest notices at the top of the window, each with what to do about it. Exceptions
become notices through :func:`notice_from_error`, which knows the advice for each device's
typed errors.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from enum import StrEnum

from PySide6 import QtCore, QtWidgets

log = logging.getLogger(__name__)

MAX_SHOWN = 4


class Level(StrEnum):
    INFO = "info"
    WARNING = "warning"
    ERROR = "error"


@dataclass(frozen=True)
class Notice:
    """What happened (``title``, ``message``) and what the operator should do (``advice``)."""

    level: Level
    title: str
    message: str
    advice: str = ""
    time_s: float = field(default_factory=time.time)


def advice_for(error: BaseException) -> str:
    """What the operator should do about ``error`` or the error that caused it (empty when
    there is nothing to add)."""
    from devices.base import errors as base
    from devices.camera import base as camera
    from devices.table import errors as table

    if isinstance(error, table.TableAlarm):
        return "Check the table is free to turn, then Unlock or Home it in Mission > Set-up."
    advice: list[tuple[type[BaseException], str]] = [
        (camera.CameraUnavailable, "Check the camera's USB 3 cable and power, or choose "
         "the simulated camera in Devices."),
        (camera.CameraDisconnected, "Check the camera's cable and power, then Connect again."),
        (camera.CameraTimeout, "The camera stopped sending frames: reconnect it."),
        (camera.CameraFormatError, "Choose another session folder for the replay camera."),
        (camera.CameraEnded, "The replay reached the end of its session: Connect again to "
         "replay it once more."),
        (table.TableDisconnected, "Check the table's USB cable and choose its port in Devices."),
        (table.TableTimeout, "Is the table's controller powered and is this its port?"),
        (table.TableHeld, "Resume or reset the table in Mission > Set-up."),
        (table.TableMissedTarget, "Check nothing blocks the table, then home it."),
        (base.BaseAuthRejected, "The base refused this computer's key: check the key folder "
         "in Devices and that the base lists this client."),
        (base.KeyFileError, "Choose the folder holding client.key_secret and base.key in "
         "Devices."),
        (base.InsecureEndpoint, "A base on the network needs CURVE keys: set the key folder "
         "in Devices."),
        (base.BaseOffline, "Check the base is powered and on the network, and its endpoint "
         "in Devices."),
        (base.BaseStopped, "The base is stopped: clear the area, then Reset the base."),
        (base.NavigationFailed, "Check the path to the station is clear, then resume."),
    ]  # fmt: skip
    for kind, text in advice:
        if isinstance(error, kind):
            return text
    cause = error.__cause__
    return advice_for(cause) if cause is not None and cause is not error else ""


def notice_from_error(title: str, error: BaseException, level: Level = Level.ERROR) -> Notice:
    """A notice for ``error``: its text as the message, the advice for its type."""
    message = str(error) or type(error).__name__
    return Notice(level, title, message, advice_for(error))


class Notifier(QtCore.QObject):
    """The sink: post notices from the GUI thread; the panel shows them."""

    posted = QtCore.Signal(object)

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.history: list[Notice] = []

    def post(self, notice: Notice) -> None:
        """Show ``notice``; any command-line instruction in it is put in the GUI's words."""
        from dataclasses import replace

        from ui.wording import gui_text

        notice = replace(notice, message=gui_text(notice.message), advice=gui_text(notice.advice))
        self.history.append(notice)
        logger = log.error if notice.level is Level.ERROR else log.info
        logger("%s: %s %s", notice.title, notice.message, notice.advice)
        self.posted.emit(notice)

    def error(self, title: str, error: BaseException) -> None:
        self.post(notice_from_error(title, error))

    def warn(self, title: str, message: str, advice: str = "") -> None:
        self.post(Notice(Level.WARNING, title, message, advice))

    def info(self, title: str, message: str) -> None:
        self.post(Notice(Level.INFO, title, message))


_STYLE = {
    Level.INFO: "background:#e8f1fb; border:1px solid #9cc3ea;",
    Level.WARNING: "background:#fff4d6; border:1px solid #e0b84c;",
    Level.ERROR: "background:#fde2e1; border:1px solid #d9534f;",
}


class NoticeCard(QtWidgets.QFrame):
    """One notice: level, title and message, advice below, a close button."""

    def __init__(self, notice: Notice, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.notice = notice
        self.setObjectName("noticeCard")
        self.setStyleSheet(f"#noticeCard {{{_STYLE[notice.level]} border-radius:4px;}}")
        stamp = time.strftime("%H:%M:%S", time.localtime(notice.time_s))
        text = f"<b>{notice.level.value.upper()} · {notice.title}</b> ({stamp}): {notice.message}"
        if notice.advice:
            text += f"<br><i>What to do:</i> {notice.advice}"
        self.label = QtWidgets.QLabel(text)
        self.label.setWordWrap(True)
        self.label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        close = QtWidgets.QToolButton()
        close.setText("✕")
        close.setToolTip("Dismiss")
        close.setAutoRaise(True)
        close.clicked.connect(self.dismiss)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(8, 4, 4, 4)
        layout.addWidget(self.label, 1)
        layout.addWidget(close, 0, QtCore.Qt.AlignmentFlag.AlignTop)

    def dismiss(self) -> None:
        self.hide()
        self.deleteLater()


class NotificationPanel(QtWidgets.QWidget):
    """The newest notices, newest first; older ones drop off (the log keeps them)."""

    def __init__(self, notifier: Notifier, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self._layout = QtWidgets.QVBoxLayout(self)
        self._layout.setContentsMargins(0, 0, 0, 0)
        self._layout.setSpacing(4)
        notifier.posted.connect(self.show_notice)
        self.setVisible(False)

    def cards(self) -> list[NoticeCard]:
        return [card for card in self.findChildren(NoticeCard) if not card.isHidden()]

    @QtCore.Slot(object)
    def show_notice(self, notice: Notice) -> None:
        self._layout.insertWidget(0, NoticeCard(notice))
        while self._layout.count() > MAX_SHOWN:
            item = self._layout.takeAt(self._layout.count() - 1)
            widget = item.widget() if item is not None else None
            if widget is not None:
                widget.hide()
                widget.deleteLater()
        self.setVisible(True)

    def clear(self) -> None:
        for card in self.cards():
            card.hide()
            card.deleteLater()
        self.setVisible(False)
