"""The Calibrate and Results pages until the workstation GUI's widgets land (see
:mod:`ui.pages`): each offers what the core can already do, nothing pretended.

- :class:`CalibrationSummaryPage`: open a ``calibration.json`` and read what it holds.
- :class:`SessionsPage`: the session folders on this computer, each checked with
  :func:`fieldapp.verify.verify_session` on a worker.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PySide6 import QtWidgets

from ui.workers import WorkerSet

if TYPE_CHECKING:
    from fieldapp.io.calibration import Calibration
    from fieldapp.verify import VerifyReport
    from ui.context import AppContext


def calibration_lines(calibration: Calibration) -> list[str]:
    """What a calibration holds, one line per fact (lengths in mm)."""
    camera = calibration.depth_camera.intrinsics()
    lines = [
        f"depth camera {camera.width} x {camera.height} px, fx {camera.fx:.2f}, "
        f"fy {camera.fy:.2f}, cx {camera.cx:.2f}, cy {camera.cy:.2f}",
    ]
    step = calibration.view_step
    lines.append(
        "view step: not calibrated"
        if step is None
        else f"view step {step.angle_deg:g} deg, {step.views_per_turn} views per turn"
    )
    stations = calibration.stations
    if stations is None:
        lines.append("stations: not calibrated")
    else:
        lines.append(f"reference station {stations.reference}")
        for station, T in sorted(stations.to_reference.items()):
            offset_mm = 1000.0 * float(np.linalg.norm(np.asarray(T)[:3, 3]))
            lines.append(f"  station {station}: {offset_mm:.0f} mm from the reference")
    lines.append("ground: " + ("calibrated" if calibration.ground else "not calibrated"))
    return lines


class CalibrationSummaryPage(QtWidgets.QWidget):
    """Open a calibration file and show it; solving is ``fieldapp calibrate`` for now."""

    def __init__(self, context: AppContext, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.context = context
        intro = QtWidgets.QLabel(
            "<h2>Calibrate</h2>The calibration wizard comes with the workstation GUI. Until "
            "then, solve with <tt>fieldapp calibrate intrinsics|views|stations</tt> and check "
            "the result here."
        )
        intro.setWordWrap(True)
        open_button = QtWidgets.QPushButton("Open calibration.json...")
        open_button.clicked.connect(self.choose_file)
        self.text = QtWidgets.QPlainTextEdit(readOnly=True)
        self.text.setPlaceholderText("No calibration open.")
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(intro)
        layout.addWidget(open_button, 0)
        layout.addWidget(self.text, 1)

    def choose_file(self) -> None:
        start = self.context.ui_state.last_folder("calibration")
        name, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Open a calibration", str(start), "Calibration (*.json)"
        )
        if name:
            self.context.ui_state.set_last_folder("calibration", Path(name))
            self.open_file(Path(name))

    def open_file(self, path: Path) -> None:
        from fieldapp.errors import FieldappError
        from fieldapp.io.calibration import load_calibration

        try:
            calibration = load_calibration(path)
        except FieldappError as error:
            self.text.setPlainText(f"{path}: not usable\n{error}")
            self.context.notifier.error(f"Calibration {path.name}", error)
            return
        self.text.setPlainText("\n".join([str(path), *calibration_lines(calibration)]))


class SessionsPage(QtWidgets.QWidget):
    """Session folders on this computer; select one to check it completely."""

    def __init__(self, context: AppContext, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.context = context
        self._workers = WorkerSet()
        intro = QtWidgets.QLabel(
            "<h2>Results</h2>Reconstruction and trait tables come with the workstation GUI. "
            "Here: the sessions recorded on this computer, each checked against the session "
            "format. Reconstruct with <tt>fieldapp reconstruct SESSION</tt>."
        )
        intro.setWordWrap(True)
        self.sessions = QtWidgets.QListWidget()
        self.sessions.currentTextChanged.connect(self._selected)
        refresh = QtWidgets.QPushButton("Refresh")
        refresh.clicked.connect(self.refresh)
        open_button = QtWidgets.QPushButton("Open session folder...")
        open_button.clicked.connect(self.choose_folder)
        self.report = QtWidgets.QPlainTextEdit(readOnly=True)
        buttons = QtWidgets.QHBoxLayout()
        buttons.addWidget(refresh)
        buttons.addWidget(open_button)
        buttons.addStretch(1)
        split = QtWidgets.QSplitter()
        split.addWidget(self.sessions)
        split.addWidget(self.report)
        split.setSizes([300, 600])
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(intro)
        layout.addLayout(buttons)
        layout.addWidget(split, 1)
        self.refresh()

    def refresh(self) -> None:
        root = self.context.settings.paths.sessions_dir
        self.sessions.clear()
        if root.is_dir():
            found = sorted(p for p in root.iterdir() if (p / "session.json").is_file())
            self.sessions.addItems([str(p) for p in found])

    def choose_folder(self) -> None:
        start = self.context.ui_state.last_folder(
            "sessions", self.context.settings.paths.sessions_dir
        )
        name = QtWidgets.QFileDialog.getExistingDirectory(self, "Open a session", str(start))
        if name:
            self.context.ui_state.set_last_folder("sessions", Path(name))
            self.check(Path(name))

    def _selected(self, text: str) -> None:
        if text:
            self.check(Path(text))

    def check(self, folder: Path) -> None:
        from fieldapp.verify import verify_session

        self.report.setPlainText(f"checking {folder}...")
        self._workers.run(lambda: verify_session(folder), self._show, self._failed)

    def _show(self, report: VerifyReport) -> None:
        lines = [str(report.folder), *report.summary_lines()]
        lines += [f"problem: {p}" for p in report.problems]
        lines.append("usable" if report.usable else f"not usable ({len(report.problems)} problems)")
        self.report.setPlainText("\n".join(lines))

    def _failed(self, error: BaseException) -> None:
        self.report.setPlainText(f"could not check the session: {error}")
        self.context.notifier.error("Session check", error)

    def shutdown(self) -> None:
        self._workers.wait(10.0)
