"""One notification sink for the whole window: errors, warnings and news with their advice.

Anything that goes wrong (a device that fails to connect, a mission that stops, a bad file)
is posted to the :class:`Notifier` as a :class:`Notice`. The strip that shows them
(:mod:`ui.notice_area`) has a fixed height, so a notice never pushes the page down: errors
stay until dismissed, news expires after :data:`LIFETIME_S`; the log dock keeps them all.
A notice carries a ``topic`` (``"mission"``): a newer notice on the same topic replaces the
open one, so a stale "Mission not started" goes once the mission completes.
"""

from __future__ import annotations

import html
import logging
import time
from dataclasses import dataclass, field, replace
from enum import StrEnum

from PySide6 import QtCore

from ui.advice import advice_for

log = logging.getLogger(__name__)

__all__ = ["Level", "Notice", "Notifier", "advice_for", "notice_from_error"]


class Level(StrEnum):
    INFO = "info"
    WARNING = "warning"
    ERROR = "error"


LIFETIME_S: dict[Level, float | None] = {Level.INFO: 8.0, Level.WARNING: 30.0, Level.ERROR: None}
"""How long a notice stays in the strip; ``None``: until the operator dismisses it."""


@dataclass(frozen=True)
class Notice:
    """What happened (``title``, ``message``) and what the operator should do (``advice``);
    ``topic`` groups notices about one thing (a newer one replaces the open one)."""

    level: Level
    title: str
    message: str
    advice: str = ""
    topic: str = ""
    time_s: float = field(default_factory=time.time)

    def text(self) -> str:
        """One line: the title, then the message (never the title twice)."""
        return f"{self.title}: {self.message}" if self.message else self.title


def without_title(title: str, message: str) -> str:
    """``message`` without a leading repetition of ``title`` ("Mission complete" and
    "mission complete: 16 captures" -> "16 captures")."""
    head = title.strip().lower()
    if head and message.lower().startswith(head):
        rest = message[len(head) :].lstrip(" :-·")
        return rest[:1].upper() + rest[1:] if rest else message
    return message


def notice_from_error(
    title: str, error: BaseException, level: Level = Level.ERROR, topic: str = ""
) -> Notice:
    """A notice for ``error``: its text as the message, the advice for its cause."""
    message = str(error) or type(error).__name__
    return Notice(level, title, message, advice_for(error), topic)


class Notifier(QtCore.QObject):
    """The sink: post notices from the GUI thread; the panel shows them, the log keeps them."""

    posted = QtCore.Signal(object)

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.history: list[Notice] = []

    def post(self, notice: Notice) -> None:
        """Show ``notice``; any command-line instruction in it is put in the GUI's words."""
        from ui.wording import gui_text

        message = without_title(notice.title, gui_text(notice.message))
        notice = replace(notice, message=message, advice=gui_text(notice.advice))
        self.history.append(notice)
        logger = log.error if notice.level is Level.ERROR else log.info
        logger("%s %s", notice.text(), notice.advice)
        self.posted.emit(notice)

    def error(self, title: str, error: BaseException, topic: str = "") -> None:
        self.post(notice_from_error(title, error, topic=topic))

    def warn(self, title: str, message: str, advice: str = "", topic: str = "") -> None:
        self.post(Notice(Level.WARNING, title, message, advice, topic))

    def info(self, title: str, message: str, topic: str = "") -> None:
        self.post(Notice(Level.INFO, title, message, topic=topic))


STYLE = {
    Level.INFO: "background:#e8f1fb; border:1px solid #9cc3ea;",
    Level.WARNING: "background:#fff4d6; border:1px solid #e0b84c;",
    Level.ERROR: "background:#fde2e1; border:1px solid #d9534f;",
}


def stamp(notice: Notice) -> str:
    return time.strftime("%H:%M:%S", time.localtime(notice.time_s))


def rich_text(notice: Notice, max_chars: int | None = None) -> str:
    """The notice as the strip shows it: level and title in bold, the message (cut to
    ``max_chars`` with "…"), then the advice."""
    text = f"<b>{notice.level.value.upper()} · {notice.title}</b> ({stamp(notice)})"
    message = notice.message
    if max_chars is not None and len(message) > max_chars:
        message = message[: max_chars - 1].rstrip() + "…"
    if message:
        text += f": {html.escape(message)}"
    if notice.advice:
        text += f"<br><i>What to do:</i> {html.escape(notice.advice)}"
    return text
