"""Choosing the captures a view or station calibration solves from: an existing session
folder (e.g. ``fieldapp simulate --scene checkerboard``), or a new session captured here from
the live camera (:class:`~fieldapp.io.writer.SessionWriter`, one capture per station and view
the operator sets). Selecting a capture shows it with the board's corners drawn.

The folder last loaded is remembered (QSettings, :mod:`ui.calibration.remembered`) and loaded
again when the next wizard opens, so a session is chosen once for the view, station and ground
wizards."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from PySide6 import QtWidgets

from devices.camera.stream import FrameStream
from fieldapp.calib.board import Board
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration
from fieldapp.io.session import Session, load_session
from fieldapp.io.writer import SessionWriter
from ui.calibration.live import BoardPreview
from ui.calibration.remembered import SESSION_KEY, remembered_session
from ui.state import UiState

__all__ = ["SESSION_KEY", "SessionPage", "remembered_session"]


class SessionPage(QtWidgets.QWizardPage):
    """``session`` once a usable session is chosen or captured."""

    def __init__(
        self,
        board: Callable[[], Board],
        stream: FrameStream | None = None,
        calibration: Callable[[], Calibration | None] = lambda: None,
        ui_state: UiState | None = None,
    ) -> None:
        super().__init__()
        self.setTitle("Captures to calibrate from")
        self.board, self.stream, self.calibration = board, stream, calibration
        self.ui_state = ui_state
        self.session: Session | None = None
        self.writer: SessionWriter | None = None
        self.folder = QtWidgets.QLineEdit()
        self.folder.setPlaceholderText("session folder")
        browse = QtWidgets.QPushButton("Choose…")
        browse.clicked.connect(self._browse)
        load = QtWidgets.QPushButton("Load")
        load.clicked.connect(lambda: self._try(lambda: self.load(Path(self.folder.text()))))
        self.captures = QtWidgets.QListWidget()
        self.captures.currentRowChanged.connect(self._show_capture)
        self.preview = BoardPreview(board())
        self.status = QtWidgets.QLabel("Choose a session folder, or capture a new one.")
        self.status.setWordWrap(True)
        row = QtWidgets.QHBoxLayout()
        for widget in (self.folder, browse, load):
            row.addWidget(widget)
        layout = QtWidgets.QGridLayout(self)
        layout.addLayout(row, 0, 0, 1, 2)
        layout.addWidget(self.captures, 1, 0)
        layout.addWidget(self.preview, 1, 1)
        if stream is not None:
            layout.addWidget(self._capture_box(), 2, 0, 1, 2)
        layout.addWidget(self.status, 3, 0, 1, 2)
        layout.setColumnStretch(1, 2)

    def load(self, folder: Path) -> Session:
        """Use the session in ``folder``; raises FieldappError when it is not usable."""
        self.session = load_session(folder)
        self.folder.setText(str(folder))
        self.captures.clear()
        for capture in self.session.captures:
            target = capture.key[2]
            self.captures.addItem(
                f"station {capture.station} view {capture.view}"
                + (f" ({target})" if target else "")
            )
        self.status.setText(f"{self.session.id}: {len(self.session.captures)} captures")
        if self.ui_state is not None:
            self.ui_state.set_value(SESSION_KEY, str(folder))
        self.completeChanged.emit()
        return self.session

    def capture(self, station: int, view: int) -> None:
        """Add the newest frame as (station, view) to the session being captured."""
        frame = self.stream.latest() if self.stream is not None else None
        if frame is None:
            raise FieldappError("no frame from the camera yet")
        if self.writer is None:
            calibration = self.calibration()
            if calibration is None:
                raise FieldappError(
                    "a new session needs the rig's calibration file (view_step, stations)"
                )
            folder = Path(self.folder.text().strip() or "calibration-session")
            self.writer = SessionWriter.create(folder, folder.name, calibration)
        self.writer.add_capture(station, view, frame.depth_m, frame.color, ir=frame.ir)
        self.load(self.writer.session.folder)

    def isComplete(self) -> bool:
        return self.session is not None

    def initializePage(self) -> None:
        self.preview.board = self.board()
        self.load_remembered()

    def load_remembered(self) -> None:
        """Load the folder another wizard chose, unless one is chosen or typed here."""
        remembered = remembered_session(self.ui_state)
        if self.session is None and not self.folder.text().strip() and remembered is not None:
            self._try(lambda: self.load(remembered))

    def cleanupPage(self) -> None:
        self.preview.stop()

    def _capture_box(self) -> QtWidgets.QWidget:
        box = QtWidgets.QGroupBox("Capture a new session from the camera (into the folder above)")
        station, view = QtWidgets.QSpinBox(), QtWidgets.QSpinBox()
        station.setRange(1, 99)
        view.setRange(0, 63)
        take = QtWidgets.QPushButton("Take capture")
        take.clicked.connect(lambda: self._try(lambda: self.capture(station.value(), view.value())))
        row = QtWidgets.QHBoxLayout(box)
        for widget in (QtWidgets.QLabel("station"), station, QtWidgets.QLabel("view"), view, take):
            row.addWidget(widget)
        return box

    def _show_capture(self, row: int) -> None:
        if self.session is None or row < 0:
            return
        images = self.session.read_capture(self.session.captures[row])
        self.preview.show_image(images.color)

    def _browse(self) -> None:
        start = remembered_session(self.ui_state)
        name = QtWidgets.QFileDialog.getExistingDirectory(
            self, "Session folder", str(start.parent) if start is not None else ""
        )
        if name:
            self._try(lambda: self.load(Path(name)))

    def _try(self, action: Callable[[], object]) -> None:
        try:
            action()
        except FieldappError as error:
            self.status.setText(f"⚠ {error}")
