"""A capture's depth, large: double-click a thumbnail of the mission grid.

The session folder's ``session.json`` lists each capture as soon as its images are written,
so a capture can be opened while the mission runs. The depth is colour-mapped (turbo)
between its 2nd and 98th percentiles (black: no measurement), with a colour bar in metres.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6 import QtCore, QtWidgets

from fieldapp.errors import FieldappError
from ui.live.frame_math import depth_indices, depth_lut

LEVEL_PERCENTILES = (2.0, 98.0)


def read_view_depth(folder: Path, station: int, view: int) -> NDArray[np.float32]:
    """(H, W) float32 metres of ``station`` ``view`` in the session ``folder`` (NaN: none)."""
    from fieldapp.io.session import load_session

    session = load_session(folder)
    for capture in session.captures:
        board = getattr(capture, "target", None)  # a calibration board's capture
        if (capture.station, capture.view) == (station, view) and not board:
            return session.read_capture(capture).depth_m
    raise FieldappError(f"{folder}: station {station} view {view} is not captured yet")


def depth_levels_m(depth_m: NDArray[np.float32]) -> tuple[float, float]:
    """The colour range: the valid depths' percentiles (a 1 cm range at least)."""
    valid = depth_m[np.isfinite(depth_m) & (depth_m > 0)]
    if valid.size == 0:
        return 0.5, 4.5
    low, high = (float(v) for v in np.percentile(valid, LEVEL_PERCENTILES))
    return low, max(high, low + 0.01)


class DepthViewer(QtWidgets.QDialog):
    """One capture's depth in a window of its own (closing deletes it)."""

    def __init__(
        self, title: str, depth_m: NDArray[np.float32], parent: QtWidgets.QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle(title)
        self.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose)
        self.levels_m = depth_levels_m(depth_m)
        graphics = pg.GraphicsLayoutWidget()
        plot = graphics.addPlot(row=0, col=0, title=title)
        plot.setAspectLocked(True)
        plot.invertY(True)
        plot.hideAxis("left")
        plot.hideAxis("bottom")
        self.image = pg.ImageItem(axisOrder="row-major")
        plot.addItem(self.image)
        colour_map = pg.colormap.get("turbo")
        bar = pg.ColorBarItem(
            values=self.levels_m, colorMap=colour_map, interactive=False, label="depth (m)",
            colorMapMenu=False,
        )  # fmt: skip
        graphics.addItem(bar, row=0, col=1)
        self.image.setLookupTable(depth_lut(colour_map.getLookupTable(nPts=255, alpha=False)))
        self.image.setImage(depth_indices(depth_m, *self.levels_m), levels=(0, 255))
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(graphics)
        self.resize(900, 760)
