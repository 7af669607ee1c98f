"""The reconstruction off the GUI: it runs in a child process
(:func:`fieldapp.recon.process.reconstruct_in_process`: Open3D's native work would otherwise
stall the GUI thread), a :class:`ui.workers.Job` relays every :class:`Progress` to the GUI
thread as a signal and then reads the results back, and cancelling stops the child at its next
step boundary."""

from __future__ import annotations

import logging
from collections.abc import Generator
from dataclasses import dataclass
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.io.session import Session
from fieldapp.recon.outputs import existing_outputs
from fieldapp.recon.progress import Progress
from fieldapp.recon.settings import ReconstructionSettings
from ui.results.data import PlotResults, load_results_dir
from ui.results.scene import CloudScene, build_scene
from ui.workers import Job, process_events_until

log = logging.getLogger(__name__)


@dataclass
class Outcome:
    """A finished reconstruction, the folder its files were written to, and what the panel
    shows of it (prepared on the worker, so the GUI thread only hands arrays to widgets)."""

    session: Session
    results_dir: Path
    plot: PlotResults
    scene: CloudScene


def default_results_dir(session_folder: Path) -> Path:
    """``<session>-results`` beside the session folder (the session itself is left as it is)."""
    return session_folder.with_name(f"{session_folder.name}-results")


def free_results_dir(folder: Path) -> Path:
    """``<folder>-2``, ``-3``, ...: the first beside ``folder`` that does not exist yet."""
    number = 2
    while (candidate := folder.with_name(f"{folder.name}-{number}")).exists():
        number += 1
    return candidate


def ask_overwrite(parent: QtWidgets.QWidget | None, folder: Path, existing: list[Path]) -> str:
    """Ask whether to replace the results in ``folder``: ``"replace"``, ``"keep both"`` (a new
    folder beside it) or ``"cancel"``."""
    box = QtWidgets.QMessageBox(parent)
    box.setIcon(QtWidgets.QMessageBox.Icon.Question)
    box.setWindowTitle("Results already there")
    box.setText(f"{folder} already holds results. Replace them?")
    box.setInformativeText(
        f"Replace: the new run overwrites {', '.join(p.name for p in existing)} when it "
        f"finishes.\nKeep both: the new run goes to {free_results_dir(folder).name}."
    )
    roles = QtWidgets.QMessageBox.ButtonRole
    replace = box.addButton("Replace", roles.DestructiveRole)
    keep_both = box.addButton("Keep both", roles.AcceptRole)
    cancel = box.addButton(QtWidgets.QMessageBox.StandardButton.Cancel)
    answers: dict[QtWidgets.QAbstractButton, str] = {
        replace: "replace",
        keep_both: "keep both",
        cancel: "cancel",
    }
    box.setDefaultButton(keep_both)
    box.exec()
    return answers.get(box.clickedButton(), "cancel")


def choose_results_dir(parent: QtWidgets.QWidget | None, folder: Path) -> Path | None:
    """Where to write a new run: ``folder`` when it holds no results, else what the user
    answers (``folder`` to replace, a new folder beside it, or ``None``: cancelled)."""
    existing = existing_outputs(folder) if folder.is_dir() else []
    if not existing:
        return folder
    answer = ask_overwrite(parent, folder, existing)
    if answer == "replace":
        return folder
    return free_results_dir(folder) if answer == "keep both" else None


def reconstruction_steps(
    session: Session, settings: ReconstructionSettings, results_dir: Path
) -> Generator[Progress, None, Outcome]:
    """The reconstruction in its own process, then its files read back for display. Closing
    this generator cancels the child process."""
    from fieldapp.recon.process import reconstruct_in_process  # the pipeline, when run

    yield from reconstruct_in_process(session.folder, settings, results_dir)
    plot = load_results_dir(results_dir)
    plot.session_folder = session.folder
    return Outcome(session, results_dir, plot, build_scene(plot))


class ReconstructionRunner(QtCore.QObject):
    """Runs one reconstruction at a time; its signals arrive on the GUI thread."""

    progressed = QtCore.Signal(object)
    """A :class:`Progress`."""
    succeeded = QtCore.Signal(object)
    """An :class:`Outcome`."""
    failed = QtCore.Signal(str)
    cancelled = QtCore.Signal()

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self._job: Job | None = None

    @property
    def running(self) -> bool:
        return self._job is not None

    def start(self, session: Session, settings: ReconstructionSettings, results_dir: Path) -> None:
        """Reconstruct ``session`` into ``results_dir``; refused while one is running."""
        if self._job is not None:
            raise FieldappError("a reconstruction is already running")
        steps = reconstruction_steps(session, settings, results_dir)
        self._job = Job(
            lambda: steps,
            on_progress=self.progressed.emit,
            on_done=self._on_returned,
            on_error=self._on_errored,
            on_cancelled=self.cancelled.emit,
            on_finished=self._on_finished,
        )
        self._job.start()

    def cancel(self) -> None:
        """Ask the work to stop at its next step boundary (``cancelled`` follows; the steps
        are closed on the worker, which stops the child process)."""
        if self._job is not None:
            self._job.cancel()

    def wait(self, timeout_s: float = 30.0) -> bool:
        """Process events until the run has ended; False on timeout."""
        return process_events_until(lambda: self._job is None, timeout_s)

    def _on_returned(self, outcome: Outcome) -> None:
        self.succeeded.emit(outcome)

    def _on_errored(self, error: BaseException) -> None:
        if isinstance(error, FieldappError):
            message = str(error)
        else:
            log.error("reconstruction failed", exc_info=error)
            message = f"unexpected error ({type(error).__name__}): {error}"
        self.failed.emit(message)

    def _on_finished(self) -> None:
        self._job = None
