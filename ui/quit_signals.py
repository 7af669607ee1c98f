"""The window closed, devices stopped, when the process is asked to end (SIGTERM, SIGINT, SIGHUP).

A Qt event loop runs in C++: Python's signal handlers only run when the interpreter next gets
control, and Ctrl-C in the terminal, ``kill``, a logout or a system shutdown used to leave the
GUI running with its devices connected (SIGTERM and SIGINT were ignored while the loop was
idle). :class:`QuitSignals` gives the signals a Python handler and ``signal.set_wakeup_fd`` a
socket that Qt watches: the signal's number wakes the event loop, which then calls
``on_signal(name)`` on the GUI thread, where the window closes as if the user had closed it,
without asking (a running mission or move is stopped, the devices shut down, the layout
saved). A second signal while that is under way ends the process at once, by the signal's
default action: the way out of a shutdown that hangs.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import socket
from collections.abc import Callable, Iterable
from types import FrameType
from typing import Any

from PySide6 import QtCore

log = logging.getLogger(__name__)

QUIT_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGTERM", "SIGINT", "SIGHUP") if hasattr(signal, name)
)


class QuitSignals(QtCore.QObject):
    """Calls ``on_signal(name)`` on the Qt thread for each signal of ``signals`` received (a
    second one of them ends the process); :meth:`restore` puts the previous handlers back.
    Create it on the main thread (only there can Python set signal handlers)."""

    def __init__(
        self,
        on_signal: Callable[[str], None],
        signals: Iterable[int] = QUIT_SIGNALS,
        parent: QtCore.QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self._on_signal = on_signal
        self._received = 0
        self._reader, self._writer = socket.socketpair()
        self._reader.setblocking(False)
        self._writer.setblocking(False)
        self._previous_fd = signal.set_wakeup_fd(self._writer.fileno(), warn_on_full_buffer=False)
        self._previous: dict[int, Any] = {}
        for number in signals:
            self._previous[number] = signal.signal(number, self._handler)
        self._notifier = QtCore.QSocketNotifier(
            self._reader.fileno(), QtCore.QSocketNotifier.Type.Read, self
        )
        self._notifier.activated.connect(self._woken)
        names = ", ".join(signal.Signals(number).name for number in self._previous)
        log.debug("%s: the window closes, the devices stop", names)

    def _handler(self, number: int, frame: FrameType | None) -> None:
        """Python's handler: counts; the wake-up byte has already been written by then."""
        self._received += 1
        if self._received > 1:  # asked again while closing: end now, by the default action
            log.warning("%s again: ending at once", signal.Signals(number).name)
            signal.signal(number, signal.SIG_DFL)
            signal.raise_signal(number)

    def _woken(self) -> None:
        with contextlib.suppress(BlockingIOError, InterruptedError):
            numbers = self._reader.recv(64)
            for number in numbers:
                if number in self._previous:
                    self._on_signal(signal.Signals(number).name)

    def restore(self) -> None:
        """The previous handlers and wake-up descriptor back, the socket closed."""
        self._notifier.setEnabled(False)
        for number, previous in self._previous.items():
            signal.signal(number, previous)
        self._previous.clear()
        signal.set_wakeup_fd(self._previous_fd)
        self._reader.close()
        self._writer.close()
