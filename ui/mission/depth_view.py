"""A capture's depth and colour, large: double-click a thumbnail of the mission grid.

The session folder's ``session.json`` lists each capture as soon as its images are written,
so a capture can be opened while the mission runs. The depth is colour-mapped (turbo)
between its 2nd and 98th percentiles (black: no measurement), with a colour bar in metres,
beside (or above) the registered colour image, as on the Live page; a depth-only capture
shows its depth alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from PySide6 import QtCore, QtGui, QtWidgets

from fieldapp.errors import FieldappError
from ui.live.frame_math import auto_levels_m, valid_depths_m
from ui.live.image_panel import DEPTH_LEVELS_M, ImagePanel

LEVEL_PERCENTILES = (2.0, 98.0)


def read_view(
    folder: Path, station: int, view: int
) -> tuple[NDArray[np.float32], NDArray[np.uint8] | None]:
    """(depth (H, W) float32 metres, NaN: none; colour (H, W, 3) uint8 or ``None`` for a
    depth-only capture) of ``station`` ``view`` in the session ``folder``."""
    from fieldapp.io.images import depth_units_to_m, read_depth_units
    from fieldapp.io.session import load_session

    session = load_session(folder)
    for capture in session.captures:
        board = getattr(capture, "target", None)  # a calibration board's capture
        if (capture.station, capture.view) != (station, view) or board:
            continue
        if capture.color is None:
            units = read_depth_units(
                session.path_of(capture.depth), expected=session.expected(capture, "depth")
            )
            return depth_units_to_m(units, session.calibration.depth_camera.depth_scale), None
        images = session.read_capture(capture)
        return images.depth_m, images.color
    raise FieldappError(f"{folder}: station {station} view {view} is not captured yet")


def read_view_depth(folder: Path, station: int, view: int) -> NDArray[np.float32]:
    """(H, W) float32 metres of ``station`` ``view`` in the session ``folder`` (NaN: none)."""
    return read_view(folder, station, view)[0]


def depth_levels_m(depth_m: NDArray[np.float32]) -> tuple[float, float]:
    """The colour range: the valid depths' percentiles (a 1 cm range at least)."""
    levels = auto_levels_m(valid_depths_m(depth_m, step=1), LEVEL_PERCENTILES, min_span_m=0.01)
    return levels if levels is not None else DEPTH_LEVELS_M


class DepthViewer(QtWidgets.QDialog):
    """One capture's depth and colour in a window of its own (closing deletes it)."""

    def __init__(
        self,
        title: str,
        depth_m: NDArray[np.float32],
        parent: QtWidgets.QWidget | None = None,
        color: NDArray[np.uint8] | None = None,
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle(title)
        self.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose)
        self.levels_m = depth_levels_m(depth_m)
        self.panel = ImagePanel()
        self.panel.set_levels(*self.levels_m)
        self.panel.show_depth(depth_m)
        self.panel.show_second("Colour" if color is not None else "None")
        if color is not None:
            self.panel.second_item.setImage(color, levels=(0, 255))
        self.panel.fit()
        self.image = self.panel.depth_item
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self.panel)
        self.resize(1200, 560)

    def showEvent(self, event: QtGui.QShowEvent) -> None:
        super().showEvent(event)
        QtCore.QTimer.singleShot(0, self.panel.fit)  # once the panel has its size
