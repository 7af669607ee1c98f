"""Wizard pages every calibration shares: what to prepare, the solve on a worker with its
quality figures and verdict, and saving into the rig's calibration with the previous kept."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from fieldapp.calib import service
from fieldapp.calib.verdict import Level, Verdict
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration
from ui.workers import Job as WorkerJob
from ui.workers import process_events_until

log = logging.getLogger(__name__)

VERDICT_STYLE = {
    Level.GOOD: "background:#2e7d32;color:white;padding:6px;font-weight:bold",
    Level.USABLE: "background:#f9a825;color:black;padding:6px;font-weight:bold",
    Level.REDO: "background:#c62828;color:white;padding:6px;font-weight:bold",
}
ERROR_STYLE = "color:#c62828;font-weight:bold"


class PreparePage(QtWidgets.QWizardPage):
    """What to prepare, as rich text, and optional extra widgets below it."""

    def __init__(self, title: str, html: str, extra: QtWidgets.QWidget | None = None) -> None:
        super().__init__()
        self.setTitle(title)
        text = QtWidgets.QLabel(html)
        text.setWordWrap(True)
        text.setTextFormat(QtCore.Qt.TextFormat.RichText)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(text)
        if extra is not None:
            layout.addWidget(extra)
        layout.addStretch(1)


Job = Callable[[], Any]
"""The solve itself, run on a worker: it holds plain data only, never a widget."""


class SolvePage(QtWidgets.QWizardPage):
    """When shown, ``prepare()`` runs on the GUI thread (it reads the widgets and the files in
    force, and may raise a :class:`FieldappError` that is shown at once) and returns the
    :data:`Job`, which runs on a worker; ``describe(result)`` gives the figures' lines and the
    verdict. The wizard moves on only after a successful solve."""

    def __init__(
        self,
        prepare: Callable[[], Job],
        describe: Callable[[Any], tuple[list[str], Verdict]],
        picture: QtWidgets.QWidget | None = None,
        show_picture: Callable[[Any], None] | None = None,
    ) -> None:
        super().__init__()
        self.setTitle("Solve and check the quality")
        self.prepare, self.describe = prepare, describe
        self.picture, self.show_picture = picture, show_picture
        self.result: Any = None
        self.error: str | None = None
        self.worker: WorkerJob | None = None
        self.progress = QtWidgets.QProgressBar()
        self.progress.setRange(0, 0)
        self.status = QtWidgets.QLabel("")
        self.status.setWordWrap(True)
        self.figures = QtWidgets.QPlainTextEdit()
        self.figures.setReadOnly(True)
        self.verdict = QtWidgets.QLabel("")
        self.verdict.setWordWrap(True)
        self.verdict.setObjectName("verdict")
        layout = QtWidgets.QVBoxLayout(self)
        for widget in (self.progress, self.status, self.verdict):
            layout.addWidget(widget)
        if picture is None:
            layout.addWidget(self.figures, 1)
        else:  # the figures beside the pictures of the result
            split = QtWidgets.QSplitter()
            split.addWidget(self.figures)
            split.addWidget(picture)
            split.setSizes([420, 580])
            layout.addWidget(split, 1)

    @property
    def running(self) -> bool:
        return self.worker is not None

    def initializePage(self) -> None:
        self.result, self.error = None, None
        self.figures.clear()
        self.verdict.clear()
        self.verdict.setStyleSheet("")
        self.status.setStyleSheet("")
        self.status.setText("solving…")
        try:
            job = self.prepare()
        except FieldappError as error:
            self._failed(error)
            self.progress.hide()
            self.completeChanged.emit()
            return
        self.progress.show()
        self.worker = WorkerJob(
            job, on_done=self._solved, on_error=self._failed, on_finished=self._finished
        )
        self.completeChanged.emit()
        self.worker.start()

    def isComplete(self) -> bool:
        return self.result is not None and not self.running

    def wait(self, timeout_s: float = 60.0) -> bool:
        return process_events_until(lambda: self.worker is None, timeout_s)

    def _solved(self, result: Any) -> None:
        lines, verdict = self.describe(result)
        self.result = result
        self.status.setText("solved")
        self.figures.setPlainText("\n".join(lines))
        self.verdict.setText(verdict.text())
        self.verdict.setStyleSheet(VERDICT_STYLE[verdict.level])
        if self.show_picture is not None:
            self.show_picture(result)

    def _failed(self, error: BaseException) -> None:
        if not isinstance(error, FieldappError):
            log.error("calibration solve failed", exc_info=error)
        self.error = str(error)
        self.status.setText(f"Cannot calibrate: {error}")
        self.status.setStyleSheet(ERROR_STYLE)
        self.verdict.setText("Redo: go back and fix what is said above")
        self.verdict.setStyleSheet(VERDICT_STYLE[Level.REDO])

    def _finished(self) -> None:
        self.worker = None
        self.progress.hide()
        self.completeChanged.emit()


class CalibrationWizard(QtWidgets.QWizard):
    """What every calibration wizard shares, shown as a page of the Calibrate area (see
    :class:`ui.calibration.workspace.Workspace`) or, in tests, as a window of its own:

    - Esc never closes it (Esc is the application's STOP, see ``ui/stop_everywhere.py``);
    - Back is disabled while the solve runs, so a solve under way is never left behind;
    - Cancel while solving asks first (``ask(question) -> bool``, a message box by default);
    - closing waits for the solve and stops the live previews (:meth:`previews`).

    Subclasses set :attr:`solve` (their :class:`SolvePage`) before adding their pages."""

    solve: SolvePage

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.ask: Callable[[str], bool] = self._ask
        self.setOption(QtWidgets.QWizard.WizardOption.NoBackButtonOnStartPage, True)
        self.currentIdChanged.connect(lambda _: self._update_back())

    @property
    def solving(self) -> bool:
        return self.solve.running

    def previews(self) -> list[Any]:
        """The live previews (``stop()``-able) to stop when the wizard closes."""
        return []

    def catch_up(self) -> None:
        """Take in what changed while the wizard was not shown (called each time it is opened;
        nothing by default)."""

    def watch_solve(self) -> None:
        """Keep Back disabled while ``solve`` runs (call once its page is added)."""
        self.solve.completeChanged.connect(self._update_back)

    def reject(self) -> None:
        """Cancel: while a solve runs, only when the operator agrees to lose it."""
        question = "A solve is running. Close this calibration and lose its result?"
        if self.solving and not self.ask(question):
            return
        super().reject()

    def done(self, result: int) -> None:
        for preview in self.previews():
            preview.stop()
        self.solve.wait()
        super().done(result)

    def keyPressEvent(self, event: QtGui.QKeyEvent) -> None:
        if event.key() == QtCore.Qt.Key.Key_Escape:
            event.ignore()  # a dialog would close on Esc: here Esc is STOP, nothing else
            return
        super().keyPressEvent(event)

    def _update_back(self) -> None:
        if self.currentPage() is self.solve and self.solving:
            self.button(QtWidgets.QWizard.WizardButton.BackButton).setEnabled(False)

    def _ask(self, question: str) -> bool:
        answer = QtWidgets.QMessageBox.question(self, self.windowTitle(), question)
        return answer == QtWidgets.QMessageBox.StandardButton.Yes


class SavePage(QtWidgets.QWizardPage):
    """Writes ``update(calibration in force or None)`` to the rig's calibration file, the
    previous file kept beside it."""

    def __init__(self, path: Path, update: Callable[[Calibration | None], Calibration]) -> None:
        super().__init__()
        self.setTitle("Save into the rig's calibration")
        self.update_calibration = update
        self.saved: Path | None = None
        self.previous: Path | None = None
        self.path = QtWidgets.QLineEdit(str(path))
        self.save_button = QtWidgets.QPushButton("Save")
        self.save_button.clicked.connect(self._save_clicked)
        self.status = QtWidgets.QLabel("The previous file is kept beside it, dated.")
        self.status.setWordWrap(True)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Calibration file"))
        row.addWidget(self.path, 1)
        row.addWidget(self.save_button)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(row)
        layout.addWidget(self.status)
        layout.addStretch(1)

    def save(self) -> Path:
        """Write the calibration; raises FieldappError (bad existing file, unwritable)."""
        path = Path(self.path.text().strip())
        self.previous = service.save(path, self.update_calibration(service.in_force(path)))
        self.saved = path
        self.status.setText(
            f"Saved to {path}"
            + (f"; previous kept as {self.previous.name}" if self.previous else "")
        )
        self.completeChanged.emit()
        return path

    def isComplete(self) -> bool:
        return self.saved is not None

    def _save_clicked(self) -> None:
        try:
            self.save()
        except FieldappError as error:
            self.status.setText(f"Not saved: {error}")
            self.status.setStyleSheet(ERROR_STYLE)
