"""The Calibrate page: the rig's calibration file, what it holds, and the four wizards, each
opened as a full page in the overview's place."""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from PySide6 import QtCore, QtWidgets

from devices.camera.stream import FrameStream
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import load_calibration
from fieldapp.settings import Settings
from ui.calibration.remembered import remembered_session
from ui.calibration.workspace import Workspace
from ui.state import UiState

if TYPE_CHECKING:
    from ui.calibration.pages import CalibrationWizard

log = logging.getLogger(__name__)

WIZARDS: list[tuple[str, str, str]] = [
    ("intrinsics", "1. Camera intrinsics (IR checkerboard)", "intrinsics_wizard:IntrinsicsWizard"),
    ("views", "2. View to view (turntable step)", "session_wizards:ViewsWizard"),
    (
        "stations",
        "3. Station to station (boards between stations)",
        "session_wizards:StationsWizard",
    ),
    ("ground", "4. Ground plane (field frame)", "session_wizards:GroundWizard"),
]
"""(key, button label, ``module:class`` under ``ui.calibration``): a wizard's module (and the
solvers it needs: OpenCV, SciPy) is imported when the wizard is opened, not at start-up."""


SECTION_NAMES = {
    "depth_camera": "Depth camera (intrinsics)",
    "view_step": "View step (turntable)",
    "stations": "Station to station",
    "ground": "Ground plane",
}
"""The calibration file's sections in the operator's words."""


def wizard_factory(where: str) -> Callable[..., CalibrationWizard]:
    module, name = where.split(":")
    factory: Callable[..., CalibrationWizard] = getattr(
        importlib.import_module(f"ui.calibration.{module}"), name
    )
    return factory


def summary(path: Path) -> str:
    """One line per section of the calibration file: present, and when it was calibrated."""
    if not path.exists():
        return f"{path}: no calibration yet (start with the intrinsics)"
    try:
        calibration = load_calibration(path)
    except FieldappError as error:
        return f"{path}: not usable:\n{error}"
    lines = [str(path)]
    for name, words in SECTION_NAMES.items():
        section = getattr(calibration, name)
        when = getattr(section, "calibrated", None) if section is not None else None
        state = (
            "missing"
            if section is None
            else (f"calibrated {when.get('date', '')}" if isinstance(when, dict) else "nominal")
        )
        lines.append(f"  {words}: {state}")
    return "\n".join(lines)


def default_calibration_path(settings: Settings) -> Path:
    """The rig's calibration file: ``calibration.json`` beside the sessions folder."""
    return settings.paths.sessions_dir.parent / "calibration.json"


class CalibratePage(QtWidgets.QStackedWidget):
    """The calibration overview (the file, what it holds, the four calibrations) and each
    opened wizard as a full page (:class:`Workspace`) in its place. ``stream`` (or a function
    giving the current one) feeds the wizards' live previews; ``ui_state`` remembers the
    session folder across the wizards (``None``: the application's QSettings).

    A wizard left for the overview stays open (a solve keeps running) and its button says
    where it stands; it closes with its own Cancel or Finish, back to the overview."""

    def __init__(
        self,
        calibration_path: Path,
        stream: FrameStream | Callable[[], FrameStream | None] | None = None,
        serial: str | None = None,
        parent: QtWidgets.QWidget | None = None,
        ui_state: UiState | None = None,
    ) -> None:
        super().__init__(parent)
        self.stream, self.serial = stream, serial
        self.ui_state = ui_state if ui_state is not None else UiState()
        self.ask: Callable[[str], bool] = self._ask
        self.workspaces: dict[str, Workspace] = {}
        self.path = QtWidgets.QLineEdit(str(calibration_path))
        self.path.editingFinished.connect(self.refresh)
        self.state = QtWidgets.QLabel("")
        self.state.setWordWrap(True)
        self.session = QtWidgets.QLabel("")
        self.session.setWordWrap(True)
        self.buttons: dict[str, QtWidgets.QPushButton] = {}
        self.overview = self._overview()
        self.addWidget(self.overview)
        self.refresh()

    def _overview(self) -> QtWidgets.QWidget:
        overview = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(overview)
        rig = QtWidgets.QGroupBox("Rig calibration")
        rig_layout = QtWidgets.QVBoxLayout(rig)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Calibration file"))
        row.addWidget(self.path, 1)
        rig_layout.addLayout(row)
        rig_layout.addWidget(self.state)
        rig_layout.addWidget(self.session)
        layout.addWidget(rig)
        steps = QtWidgets.QGroupBox("Calibrations, in this order")
        steps_layout = QtWidgets.QVBoxLayout(steps)
        hint = QtWidgets.QLabel(
            "Each opens here as a page. <i>&lt; Calibration overview</i> (or Alt+Left on its "
            "first step) comes back and leaves it as it is, a solve under way included; "
            "its Cancel or Finish closes it. Esc is STOP, as everywhere."
        )
        hint.setWordWrap(True)
        steps_layout.addWidget(hint)
        for key, label, _ in WIZARDS:
            button = QtWidgets.QPushButton(label)
            button.setStyleSheet("text-align:left; padding:10px; font-size:14px")
            button.clicked.connect(lambda _=False, k=key: self.open_wizard(k))
            steps_layout.addWidget(button)
            self.buttons[key] = button
        layout.addWidget(steps)
        layout.addStretch(1)
        return overview

    @property
    def wizards(self) -> dict[str, CalibrationWizard]:
        """The open wizards by key (shown or left for the overview)."""
        return {key: space.wizard for key, space in self.workspaces.items()}

    @property
    def wizard(self) -> CalibrationWizard | None:
        """The wizard shown now (``None`` on the overview)."""
        current = self.currentWidget()
        return current.wizard if isinstance(current, Workspace) else None

    def refresh(self) -> None:
        self.state.setText(summary(Path(self.path.text().strip())))
        folder = remembered_session(self.ui_state)
        self.session.setText(
            "Session folder for view to view, station to station and ground: "
            + (f"{folder} (loaded when they open)" if folder else "none chosen yet")
        )
        self.update_buttons()

    @QtCore.Slot()
    def update_buttons(self) -> None:
        """Each calibration's button: its name, and where its open wizard stands."""
        for key, label, _ in WIZARDS:
            space = self.workspaces.get(key)
            self.buttons[key].setText(
                label if space is None else f"{label}   >  continue: {space.state_text()}"
            )

    def open_wizard(self, key: str) -> CalibrationWizard:
        """Show the wizard ``key`` (intrinsics, views, stations, ground) as this page, the
        one left open earlier if there is one."""
        space = self.workspaces.get(key)
        if space is None:
            space = self._workspace(key)
        space.wizard.catch_up()  # e.g. a session chosen meanwhile in another wizard
        self.setCurrentWidget(space)
        space.wizard.show()
        space.wizard.setFocus()
        return space.wizard

    def _workspace(self, key: str) -> Workspace:
        label, where = {k: (label, where) for k, label, where in WIZARDS}[key]
        stream = self.stream() if callable(self.stream) else self.stream
        wizard = wizard_factory(where)(
            Path(self.path.text().strip()),
            stream=stream,
            serial=self.serial,
            ui_state=self.ui_state,
        )
        space = Workspace(label.split(". ", 1)[-1], wizard)
        space.overview_requested.connect(self.show_overview)
        wizard.currentIdChanged.connect(lambda _: self.update_buttons())
        wizard.solve.completeChanged.connect(self.update_buttons)
        wizard.finished.connect(lambda _: self._closed(key))
        self.workspaces[key] = space
        self.addWidget(space)
        return space

    @QtCore.Slot()
    def show_overview(self) -> None:
        """Back to the overview; open wizards stay as they are."""
        self.refresh()
        self.setCurrentWidget(self.overview)

    def confirm_close(self, parent: QtWidgets.QWidget) -> bool:
        """Before the window closes: asks when a solve is running (it would be lost)."""
        running = [space.title for space in self.workspaces.values() if space.wizard.solving]
        return not running or self.ask(
            f"A calibration is solving ({', '.join(running)}). Quit and lose its result?"
        )

    def shutdown(self) -> None:
        """Close the open wizards (their workers are waited for)."""
        for space in list(self.workspaces.values()):
            space.wizard.done(QtWidgets.QDialog.DialogCode.Rejected)

    def _closed(self, key: str) -> None:
        space = self.workspaces.pop(key, None)
        if space is None:
            return
        if self.currentWidget() is space:
            self.setCurrentWidget(self.overview)
        self.removeWidget(space)
        space.deleteLater()
        self.refresh()

    def _ask(self, question: str) -> bool:
        answer = QtWidgets.QMessageBox.question(self, "Calibration", question)
        return answer == QtWidgets.QMessageBox.StandardButton.Yes
