"""Live board detection: the newest camera frame (polled with a QTimer from a
:class:`~devices.camera.stream.FrameStream`) or a still image, the board's corners found on a
worker thread and drawn on the image, a clear "board not found" state, and the coverage map
of where corners have been seen."""

from __future__ import annotations

import logging
from functools import partial
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from PySide6 import QtCore, QtGui, QtWidgets

from devices.camera.stream import FrameStream
from fieldapp.calib.board import Board, detect_corners, to_gray8
from fieldapp.calib.intrinsics import COVERAGE_GRID, missing_regions
from ui.workers import WorkerSet

log = logging.getLogger(__name__)

POLL_MS = 100
FOUND_STYLE = "background:#2e7d32;color:white;padding:4px;font-weight:bold"
MISSING_STYLE = "background:#c62828;color:white;padding:4px;font-weight:bold"


def picture_label(text: str, min_width: int, min_height: int) -> QtWidgets.QLabel:
    """A centred label for a picture, at least ``min_width`` x ``min_height``, whose pixmap is
    scaled to the room the label has: it never grows the page (nor the window)."""
    label = QtWidgets.QLabel(text)
    label.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
    label.setMinimumSize(min_width, min_height)
    ignored = QtWidgets.QSizePolicy.Policy.Ignored
    label.setSizePolicy(ignored, ignored)
    return label


def detection_image(frame_ir: NDArray[Any] | None, color: NDArray[np.uint8]) -> NDArray[Any]:
    """The image boards are found in: IR when the camera gives it (the paper calibrates the
    depth camera from IR), else the colour image."""
    return frame_ir if frame_ir is not None else color


def drawn(
    image: NDArray[Any], corners: NDArray[np.float32] | None, board: Board
) -> NDArray[np.uint8]:
    """(H, W, 3) uint8 RGB of ``image`` with the corners drawn (OpenCV's coloured rows)."""
    rgb = cv2.cvtColor(to_gray8(image), cv2.COLOR_GRAY2RGB) if image.ndim == 2 else image.copy()
    if corners is not None:
        cv2.drawChessboardCorners(rgb, board.pattern, corners.reshape(-1, 1, 2), True)
    return np.ascontiguousarray(rgb, np.uint8)


def to_pixmap(rgb: NDArray[np.uint8]) -> QtGui.QPixmap:
    height, width = rgb.shape[:2]
    image = QtGui.QImage(rgb.data, width, height, 3 * width, QtGui.QImage.Format.Format_RGB888)
    return QtGui.QPixmap.fromImage(image.copy())


class BoardPreview(QtWidgets.QWidget):
    """An image with the detected board; ``detected(image, corners or None)`` per image."""

    detected = QtCore.Signal(object, object)

    def __init__(self, board: Board, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.board = board
        self.stream: FrameStream | None = None
        self.image: NDArray[Any] | None = None
        self.corners: NDArray[np.float32] | None = None
        self._workers = WorkerSet()
        self.picture = picture_label("no image yet", 320, 265)
        self.state = QtWidgets.QLabel("")
        self.state.setObjectName("boardState")
        self.state.setWordWrap(True)  # the whole "BOARD NOT FOUND" advice, never cut off
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self.state)
        layout.addWidget(self.picture, 1)
        self.timer = QtCore.QTimer(self)
        self.timer.setInterval(POLL_MS)
        self.timer.timeout.connect(self._poll)

    @property
    def found(self) -> bool:
        return self.corners is not None

    def follow(self, stream: FrameStream | None) -> None:
        """Show the newest frames of ``stream`` (None: stop)."""
        self.stream = stream
        if stream is None:
            self.timer.stop()
        else:
            self.timer.start()

    def show_image(self, image: NDArray[Any]) -> None:
        """Detect the board in ``image`` on a worker; the result is drawn when it comes."""
        if self._workers.busy:  # one detection at a time: frames that come meanwhile are skipped
            return
        self._workers.run(
            partial(detect_corners, image, self.board),
            lambda corners: self._show(image, corners),
            lambda error: self._failed(image, error),
        )

    def show_detected(self, image: NDArray[Any], corners: NDArray[np.float32] | None) -> None:
        """Show ``image`` with corners already found (a view taken earlier): no detection."""
        self._show(image, corners)

    def wait(self, timeout_s: float = 10.0) -> bool:
        """Process events until no detection is running (for closing and tests)."""
        return self._workers.wait(timeout_s)

    def stop(self) -> None:
        self.follow(None)
        self.wait()

    def _poll(self) -> None:
        frame = self.stream.latest() if self.stream is not None else None
        if frame is not None:
            self.show_image(detection_image(frame.ir, frame.color))

    def _show(self, image: NDArray[Any], corners: NDArray[np.float32] | None) -> None:
        self.image, self.corners = image, corners
        if corners is None:
            self.state.setText(
                f"BOARD NOT FOUND: no {self.board.cols} x {self.board.rows} inner corners seen. "
                "Check the board size, that the whole board is in view, and (IR) that it is "
                "laser printed."
            )
            self.state.setStyleSheet(MISSING_STYLE)
        else:
            self.state.setText(f"Board found: {len(corners)} corners")
            self.state.setStyleSheet(FOUND_STYLE)
        pixmap = to_pixmap(drawn(image, corners, self.board))
        self.picture.setPixmap(
            pixmap.scaled(self.picture.size(), QtCore.Qt.AspectRatioMode.KeepAspectRatio)
        )
        self.detected.emit(image, corners)

    def _failed(self, image: NDArray[Any], error: BaseException) -> None:
        log.warning("board detection failed: %s", error)
        self._show(image, None)


class CoverageMap(QtWidgets.QWidget):
    """The 8 x 8 cells of the image: darker where more corners were seen, red where none."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.counts = np.zeros((COVERAGE_GRID, COVERAGE_GRID), np.int32)
        self.setMinimumSize(160, 132)

    def set_counts(self, counts: NDArray[np.int32]) -> None:
        self.counts = counts
        self.update()

    def missing_text(self) -> str:
        if not self.counts.any():
            return "no corners seen yet"
        missing = missing_regions(self.counts)
        return "still missing: " + ", ".join(missing) if missing else "every region covered"

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:
        painter = QtGui.QPainter(self)
        w, h = self.width() / COVERAGE_GRID, self.height() / COVERAGE_GRID
        top = max(int(self.counts.max()), 1)
        for row in range(COVERAGE_GRID):
            for col in range(COVERAGE_GRID):
                count = int(self.counts[row, col])
                shade = (
                    QtGui.QColor(230, 120, 120)
                    if count == 0
                    else QtGui.QColor.fromHsv(120, 160, 255 - int(150 * count / top))
                )
                painter.fillRect(QtCore.QRectF(col * w, row * h, w - 1, h - 1), shade)
        painter.end()
