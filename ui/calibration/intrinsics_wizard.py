"""The intrinsics wizard: prepare the board, capture views live (or add images), watch the
coverage, solve Zhang's calibration on a worker, judge it and save ``depth_camera``."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from PySide6 import QtWidgets

from devices.camera.stream import FrameStream
from fieldapp.calib import service
from fieldapp.calib.board import Board, detect_corners
from fieldapp.calib.intrinsics import (
    MIN_VIEWS,
    RECOMMENDED_VIEWS,
    IntrinsicsResult,
    calibrate_intrinsics,
    coverage_of,
    read_calibration_image,
)
from fieldapp.calib.verdict import Verdict, intrinsics_verdict
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration
from ui.calibration.board_form import BoardForm
from ui.calibration.live import BoardPreview, CoverageMap
from ui.calibration.pages import CalibrationWizard, PreparePage, SavePage, SolvePage
from ui.calibration.pictures import ReprojectionPicture
from ui.calibration.remembered import remembered_session
from ui.state import UiState

DEFAULT_BOARD = Board(9, 6, 40.0)
PREPARE = f"""<p>Calibrates the depth camera's lens (focal lengths, centre, distortion) by
Zhang's method from images of a checkerboard, in <b>infrared</b> as the paper does.</p>
<ul><li>Print a checkerboard (default {DEFAULT_BOARD.cols + 1} x {DEFAULT_BOARD.rows + 1}
squares, i.e. {DEFAULT_BOARD.cols} x {DEFAULT_BOARD.rows} inner corners) on a <b>laser
printer</b>: inkjet prints are often invisible in infrared. Glue it flat on a rigid board and
measure a square.</li>
<li>Hold it 0.5-0.9 m from the camera, still, and move it between captures: the centre, every
corner and edge of the image, tilted up to 40 degrees. Take {RECOMMENDED_VIEWS} or more views
({MIN_VIEWS} at the very least).</li>
<li>Without a camera, add IR images from a folder (e.g. <code>intrinsics/</code> of a session
simulated with <code>fieldapp simulate --scene checkerboard</code>).</li></ul>"""


class CapturePage(QtWidgets.QWizardPage):
    """Views of the board: taken from the live preview or added from files; a view selected
    in the list is shown with its corners (the live preview pauses) and can be removed."""

    def __init__(
        self, board_form: BoardForm, stream: FrameStream | None, ui_state: UiState | None = None
    ) -> None:
        super().__init__()
        self.setTitle("Capture views of the board")
        self.board_form, self.stream, self.ui_state = board_form, stream, ui_state
        self.views: list[tuple[str, NDArray[Any], NDArray[np.float32]]] = []
        self.preview = BoardPreview(board_form.board())
        take = QtWidgets.QPushButton("Take this view")
        take.clicked.connect(self.take)
        add = QtWidgets.QPushButton("Add images…")
        add.clicked.connect(self._ask_images)
        self.listing = QtWidgets.QListWidget()
        self.listing.currentRowChanged.connect(self.show_view)
        self.remove_button = QtWidgets.QPushButton("Remove the selected view")
        self.remove_button.clicked.connect(lambda: self.remove(self.listing.currentRow()))
        self.live_button = QtWidgets.QPushButton("Back to the live camera")
        self.live_button.clicked.connect(self.back_to_live)
        self.coverage = CoverageMap()
        self.status = QtWidgets.QLabel("")
        self.status.setWordWrap(True)
        side = QtWidgets.QVBoxLayout()
        for widget in (
            take, add, self.listing, self.remove_button, self.live_button,
            QtWidgets.QLabel("Corner coverage"), self.coverage,
        ):  # fmt: skip
            side.addWidget(widget)
        layout = QtWidgets.QGridLayout(self)
        layout.addWidget(self.preview, 0, 0)
        layout.addLayout(side, 0, 1)
        layout.addWidget(self.status, 1, 0, 1, 2)
        layout.setColumnStretch(0, 3)

    def initializePage(self) -> None:
        self.preview.board = self.board_form.board()
        self.preview.follow(self.stream)
        self._update()

    def cleanupPage(self) -> None:
        self.preview.stop()

    def take(self) -> bool:
        """Keep the preview's image if the board was found in it; say why not otherwise."""
        if self.preview.image is None or self.preview.corners is None:
            self.status.setText("Board not found in the current image: nothing taken.")
            return False
        self._add(f"view {len(self.views) + 1}", self.preview.image, self.preview.corners)
        return True

    def add_images(self, paths: list[Path]) -> list[str]:
        """Add image files; returns the names in which the board was not found."""
        board, refused = self.board_form.board(), []
        for path in paths:
            image = read_calibration_image(path)
            corners = detect_corners(image, board)
            if corners is None:
                refused.append(path.name)
            else:
                self._add(path.name, image, corners)
        if refused:
            self.status.setText(f"Board not found in {', '.join(refused)}: not added.")
        if paths:
            self.preview.show_image(read_calibration_image(paths[-1]))
        return refused

    def show_view(self, row: int) -> None:
        """Show view ``row`` as it was taken, with its corners; the live preview pauses."""
        if not 0 <= row < len(self.views):
            return
        self.preview.stop()  # no live frame (nor a detection under way) replaces it
        name, image, corners = self.views[row]
        self.preview.show_detected(image, corners)
        self.status.setText(f"{name}: {len(corners)} corners (Remove drops it)")

    def remove(self, row: int) -> None:
        """Drop view ``row`` from the calibration."""
        if not 0 <= row < len(self.views):
            return
        name = self.views.pop(row)[0]
        self.listing.takeItem(row)
        self._update()
        self.status.setText(f"{name} removed; " + self.status.text())
        self.completeChanged.emit()

    def back_to_live(self) -> None:
        self.listing.clearSelection()
        self.preview.follow(self.stream)

    def isComplete(self) -> bool:
        return len(self.views) >= MIN_VIEWS

    def _add(self, name: str, image: NDArray[Any], corners: NDArray[np.float32]) -> None:
        self.views.append((name, image, corners))
        self.listing.addItem(f"{name}: {len(corners)} corners")
        self._update()
        self.completeChanged.emit()

    def _update(self) -> None:
        if self.views:
            size = (self.views[0][1].shape[1], self.views[0][1].shape[0])
            self.coverage.set_counts(coverage_of([c for _, _, c in self.views], size))
        else:
            self.coverage.set_counts(np.zeros_like(self.coverage.counts))
        count = len(self.views)
        need = f"{MIN_VIEWS} needed" if count < MIN_VIEWS else f"{RECOMMENDED_VIEWS} recommended"
        self.status.setText(f"{count} views ({need}); {self.coverage.missing_text()}")

    def _ask_images(self) -> None:
        session = remembered_session(self.ui_state)
        start = "" if session is None else str(session / "intrinsics")
        names, _ = QtWidgets.QFileDialog.getOpenFileNames(
            self, "Board images", start, "Images (*.png *.jpg *.tif)"
        )
        try:
            self.add_images([Path(n) for n in names])
        except FieldappError as error:
            self.status.setText(str(error))


def describe(result: IntrinsicsResult) -> tuple[list[str], Verdict]:
    k = result.intrinsics
    lines = [
        f"fx {k.fx:.2f}  fy {k.fy:.2f}  cx {k.cx:.2f}  cy {k.cy:.2f} (px)",
        "distortion k1 k2 p1 p2 k3: " + " ".join(f"{d:.5f}" for d in k.distortion),
        f"RMS reprojection error {result.rms_px:.3f} px over {len(result.used)} views",
        f"corner coverage {100 * result.coverage:.0f} % of the image",
        *[
            f"  {v.name}: "
            + (f"{v.error_px:.3f} px" if v.rejected is None else f"not used: {v.rejected}")
            for v in result.views
        ],
        *[f"warning: {w}" for w in result.warnings],
    ]
    return lines, intrinsics_verdict(result)


class IntrinsicsWizard(CalibrationWizard):
    def __init__(
        self,
        calibration_path: Path,
        stream: FrameStream | None = None,
        serial: str | None = None,
        parent: QtWidgets.QWidget | None = None,
        ui_state: UiState | None = None,
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle("Calibrate the camera intrinsics")
        self.ui_state = ui_state
        self.serial = serial
        self.board_form = BoardForm(DEFAULT_BOARD)
        self.prepare = PreparePage("What to prepare", PREPARE, self.board_form)
        self.capture = CapturePage(self.board_form, stream, ui_state)
        self.reprojection = ReprojectionPicture(lambda: self.capture.views, self.board_form.board)
        self.solve = SolvePage(
            self._solve, describe, self.reprojection, self.reprojection.show_result
        )
        self.save = SavePage(calibration_path, self._update)
        for page in (self.prepare, self.capture, self.solve, self.save):
            self.addPage(page)
        self.watch_solve()

    def _solve(self) -> Callable[[], IntrinsicsResult]:
        images = [(name, image) for name, image, _ in self.capture.views]
        return partial(calibrate_intrinsics, images, self.board_form.board())

    def _update(self, current: Calibration | None) -> Calibration:
        result: IntrinsicsResult = self.solve.result
        return service.merge_intrinsics(current, result, self.board_form.board(), self.serial)

    def previews(self) -> list[Any]:
        return [self.capture.preview]
