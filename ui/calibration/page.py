"""The Calibrate page: the rig's calibration file, what it holds, and the four wizards."""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable
from pathlib import Path

from PySide6 import QtWidgets

from devices.camera.stream import FrameStream
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import load_calibration
from fieldapp.settings import Settings
from ui.state import UiState

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


def wizard_factory(where: str) -> Callable[..., QtWidgets.QWizard]:
    module, name = where.split(":")
    factory: Callable[..., QtWidgets.QWizard] = getattr(
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


class CalibratePage(QtWidgets.QWidget):
    """Launches each wizard on the calibration file; ``stream`` (or a function giving the
    current one) feeds their live previews; ``ui_state`` remembers the session folder across
    the wizards (``None``: the application's QSettings)."""

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
        self.wizard: QtWidgets.QWizard | None = None
        self.path = QtWidgets.QLineEdit(str(calibration_path))
        self.path.editingFinished.connect(self.refresh)
        self.state = QtWidgets.QLabel("")
        self.state.setWordWrap(True)
        layout = QtWidgets.QVBoxLayout(self)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Rig calibration file"))
        row.addWidget(self.path, 1)
        layout.addLayout(row)
        layout.addWidget(self.state)
        self.buttons: dict[str, QtWidgets.QPushButton] = {}
        for key, label, _ in WIZARDS:
            button = QtWidgets.QPushButton(label)
            button.clicked.connect(lambda _=False, k=key: self.open_wizard(k))
            layout.addWidget(button)
            self.buttons[key] = button
        layout.addStretch(1)
        self.refresh()

    def refresh(self) -> None:
        self.state.setText(summary(Path(self.path.text().strip())))

    def open_wizard(self, key: str) -> QtWidgets.QWizard:
        """Open the wizard ``key`` (intrinsics, views, stations, ground), non-modal."""
        factory = wizard_factory({k: where for k, _, where in WIZARDS}[key])
        stream = self.stream() if callable(self.stream) else self.stream
        wizard = factory(
            Path(self.path.text().strip()),
            stream=stream,
            serial=self.serial,
            parent=self,
            ui_state=self.ui_state,
        )
        wizard.finished.connect(lambda _: self._closed(wizard))
        self.wizard = wizard
        wizard.show()
        return wizard

    def shutdown(self) -> None:
        """Close an open wizard (its workers are waited for)."""
        if self.wizard is not None:
            self.wizard.reject()

    def _closed(self, wizard: QtWidgets.QWizard) -> None:
        self.refresh()
        if self.wizard is wizard:
            self.wizard = None
        wizard.deleteLater()
