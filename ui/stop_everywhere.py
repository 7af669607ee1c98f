"""STOP from everywhere: Esc and the STOP button act whatever dialog or wizard is open.

A modal dialog blocks every other window: a click on the main window's STOP button never
arrives, and Esc goes to the dialog (which closes). :class:`StopEverywhere` is an event filter
on the whole application that

- turns every Esc key press, in any window of the application, into STOP (the dialog stays
  open: Esc is the global STOP, dialogs close with their own buttons), and
- gives every dialog, as it is shown, its own STOP button: a small frameless window owned by
  the dialog (so the dialog's modality does not block it), placed exactly over the main
  window's STOP button, so the operator finds STOP where it always is.

Pop-ups (menus, combo-box lists) keep Esc for closing themselves, after STOP acted.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from PySide6 import QtCore, QtGui, QtWidgets

log = logging.getLogger(__name__)

FLOATING_NAME = "floatingStop"


class FloatingStop(QtWidgets.QPushButton):
    """A dialog's STOP button, drawn over the main window's one."""

    def __init__(self, anchor: QtWidgets.QPushButton, dialog: QtWidgets.QWidget) -> None:
        super().__init__(anchor.text(), dialog)
        self.setObjectName(FLOATING_NAME)
        self.setWindowFlags(
            QtCore.Qt.WindowType.Tool
            | QtCore.Qt.WindowType.FramelessWindowHint
            | QtCore.Qt.WindowType.WindowStaysOnTopHint
            | QtCore.Qt.WindowType.WindowDoesNotAcceptFocus
        )
        self.setAttribute(QtCore.Qt.WidgetAttribute.WA_ShowWithoutActivating)
        self.setStyleSheet(anchor.styleSheet())
        self.setToolTip(anchor.toolTip())
        self.anchor = anchor

    def place(self) -> None:
        """Over the anchor (global coordinates), or at the dialog's top right corner when the
        main window is not on screen."""
        anchor = self.anchor
        if anchor.isVisible() and not anchor.window().isMinimized():
            corner = anchor.mapToGlobal(QtCore.QPoint(0, 0))
            self.setGeometry(QtCore.QRect(corner, anchor.size()))
            return
        dialog = self.parentWidget()
        if dialog is not None:
            top_right = dialog.geometry().topRight()
            self.setGeometry(QtCore.QRect(top_right - QtCore.QPoint(anchor.width(), 0),
                                          anchor.size()))  # fmt: skip


class StopEverywhere(QtCore.QObject):
    """Installed on the application for ``window``; ``stop()`` is the window's STOP."""

    def __init__(
        self, window: QtWidgets.QWidget, button: QtWidgets.QPushButton, stop: Callable[[], None]
    ) -> None:
        super().__init__(window)
        self.window, self.button, self.stop = window, button, stop
        app = QtWidgets.QApplication.instance()
        if app is not None:
            app.installEventFilter(self)

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:
        kind = event.type()
        if kind == QtCore.QEvent.Type.KeyPress and isinstance(event, QtGui.QKeyEvent):
            return self._key(watched, event)
        if (
            kind == QtCore.QEvent.Type.Show
            and isinstance(watched, QtWidgets.QDialog)
            and watched.isWindow()  # a wizard shown as a page has the window's own STOP
            and self._ours(watched)
        ):
            self._float_stop(watched)
        return False

    def _key(self, watched: QtCore.QObject, event: QtGui.QKeyEvent) -> bool:
        if event.key() != QtCore.Qt.Key.Key_Escape or not isinstance(watched, QtWidgets.QWidget):
            return False
        if not self._ours(watched):
            return False
        if not event.isAutoRepeat():
            log.warning("Esc: STOP from %s", type(watched.window()).__name__)
            self.stop()
        popup = QtWidgets.QApplication.activePopupWidget()
        return popup is None  # a pop-up still closes on Esc; anything else keeps its state

    def _ours(self, widget: QtWidgets.QWidget) -> bool:
        """``widget`` is in the main window or in a window it owns (or in an ownerless one)."""
        top = widget.window()
        if top is self.window:
            return True
        owner = top.parentWidget()
        while owner is not None:
            if owner.window() is self.window:
                return True
            owner = owner.window().parentWidget()
        return top.parentWidget() is None and not isinstance(top, QtWidgets.QMainWindow)

    def _float_stop(self, dialog: QtWidgets.QDialog) -> None:
        floating = dialog.findChild(FloatingStop, FLOATING_NAME)
        if not isinstance(floating, FloatingStop):
            floating = FloatingStop(self.button, dialog)
            floating.clicked.connect(self.stop)
        floating.place()
        floating.show()
        floating.raise_()


def floating_stop(dialog: QtWidgets.QWidget) -> QtWidgets.QPushButton | None:
    """The STOP button :class:`StopEverywhere` gave ``dialog`` (``None`` if none)."""
    button = dialog.findChild(FloatingStop, FLOATING_NAME)
    return button if isinstance(button, FloatingStop) else None
