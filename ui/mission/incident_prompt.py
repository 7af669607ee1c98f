"""The operator's decision after a lost link or a blocked path (issue 23): the mission's thread
asks, the question is shown on the GUI thread, the answer goes back.

:class:`IncidentPrompt` is the runner gate's ``operator_prompt``. Called on the mission's
thread, it hands the :class:`~fieldapp.mission.incidents.Incident` to the GUI thread through a
queued signal and waits for the operator's button. The dialog is not modal, so STOP (its button
or Esc) still works while it is open; a STOP meanwhile answers "stop" and closes the dialog.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from PySide6 import QtCore, QtWidgets

from fieldapp.mission.incidents import Choice, Incident, IncidentKind

STOP = Choice.STOP
POLL_S = 0.05
"""How often the waiting mission thread looks for a STOP."""

TITLES = {
    IncidentKind.LOST_LINK: "The base lost its link",
    IncidentKind.BLOCKED_PATH: "The base cannot reach the station",
}
BUTTONS = {
    Choice.RESUME: "Resume: drive to the station again",
    Choice.SKIP_STATION: "Skip this station (capture it later with Resume session…)",
    Choice.STOP: "Stop the mission",
}


class IncidentPrompt(QtCore.QObject):
    """Asks the operator on the GUI thread; ``stopped()`` tells the waiting thread to give up."""

    asked = QtCore.Signal(object)
    """(Incident), emitted on the mission's thread, delivered on the GUI thread."""
    answered = QtCore.Signal(object)
    """(Choice), emitted on the GUI thread once the operator (or a STOP) has decided."""
    _withdrawn = QtCore.Signal()

    def __init__(
        self,
        stopped: Callable[[], bool],
        parent_widget: Callable[[], QtWidgets.QWidget | None] = lambda: None,
    ) -> None:
        super().__init__()
        self._stopped = stopped
        self._parent_widget = parent_widget
        self._answer: Choice | None = None
        self._ready = threading.Event()
        self.dialog: QtWidgets.QMessageBox | None = None
        self.asked.connect(self._show, QtCore.Qt.ConnectionType.QueuedConnection)
        self._withdrawn.connect(self._close, QtCore.Qt.ConnectionType.QueuedConnection)

    def __call__(self, incident: Incident) -> Choice:
        """On the mission's thread: the operator's choice (``STOP`` if the mission is stopped
        while waiting)."""
        self._answer = None
        self._ready.clear()
        self.asked.emit(incident)
        while not self._ready.wait(POLL_S):
            if self._stopped():
                self._withdrawn.emit()
                return Choice.STOP
        return self._answer or Choice.STOP

    def _show(self, incident: Incident) -> None:
        box = QtWidgets.QMessageBox(self._parent_widget())
        box.setIcon(QtWidgets.QMessageBox.Icon.Warning)
        box.setWindowTitle(TITLES[incident.kind])
        box.setText(f"<b>{TITLES[incident.kind]}</b>")
        box.setInformativeText(
            f"{incident.what}.\nThe base stays stopped until you decide what to do."
        )
        buttons: dict[QtWidgets.QAbstractButton, Choice] = {}
        for choice in incident.choices:
            button = box.addButton(BUTTONS[choice], QtWidgets.QMessageBox.ButtonRole.ActionRole)
            button.setObjectName(f"incident-{choice.value}")
            buttons[button] = choice
        # Closed by a button or not: closing without a choice is the safe one, stop (the base
        # stays put).
        box.finished.connect(lambda _code: self._decide(buttons.get(box.clickedButton(), STOP)))
        box.setModal(False)
        box.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose)
        self.dialog = box
        box.show()

    def _decide(self, choice: Choice) -> None:
        if self._ready.is_set():
            return
        self._answer = choice
        self._ready.set()
        self.answered.emit(choice)
        self._close()

    def _close(self) -> None:
        if self.dialog is not None:
            self.dialog.close()
            self.dialog = None
