"""The depth colour map's range: automatic (the scene's 2nd to 98th depth percentiles, so
the colours spread over what is in view) or set by hand (the two spin boxes, or dragging the
band on the histogram, which turns Auto off); a histogram of the frame's depths shows where
the range lies."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6 import QtCore, QtGui, QtWidgets

from ui.live.frame_math import auto_levels_m, depth_histogram
from ui.live.image_panel import DEPTH_LEVELS_M

HISTOGRAM_RANGE_M = (0.0, 8.0)
AUTO_HELP = (
    "Auto: the colours spread over the depths in view (their 2nd to 98th percentiles), "
    "following the scene. Off: the range stays where you set it (the two boxes, or drag "
    "the band on the histogram)."
)


class DepthRange(QtCore.QObject):
    """Owns the Auto check box, the two spin boxes and the histogram; emits
    :attr:`levels_changed` (low m, high m) whenever the range changes."""

    levels_changed = QtCore.Signal(float, float)

    def __init__(self, parent: QtWidgets.QWidget) -> None:
        super().__init__(parent)
        self.auto = QtWidgets.QCheckBox("Auto")
        self.auto.setChecked(True)
        self.auto.setToolTip(AUTO_HELP)
        self.auto.toggled.connect(self._auto_toggled)
        self.low_m = _spin(DEPTH_LEVELS_M[0])
        self.high_m = _spin(DEPTH_LEVELS_M[1])
        for spin in (self.low_m, self.high_m):
            spin.setToolTip(AUTO_HELP)
            spin.valueChanged.connect(self._typed)
        self.histogram = pg.PlotWidget()
        self.histogram.setBackground(parent.palette().color(QtGui.QPalette.ColorRole.Window))
        self.histogram.setMinimumHeight(110)
        self.histogram.setMaximumHeight(150)
        self.histogram.setMenuEnabled(False)
        self.histogram.hideButtons()
        self.histogram.setMouseEnabled(x=False, y=False)
        self.histogram.hideAxis("left")
        self.histogram.setLabel("bottom", "depth (m)")
        self.histogram.setToolTip("Depths in view; the band is the colour map's range.")
        self.curve = pg.PlotDataItem(
            stepMode="center", fillLevel=0, brush=(80, 120, 200, 160), pen=pg.mkPen(60, 90, 160)
        )
        self.histogram.addItem(self.curve)
        self.band = pg.LinearRegionItem(values=DEPTH_LEVELS_M, brush=(255, 160, 0, 50))
        self.band.sigRegionChangeFinished.connect(self._dragged)
        self.histogram.addItem(self.band)
        self.histogram.setXRange(*HISTOGRAM_RANGE_M, padding=0.0)
        self.levels_m: tuple[float, float] = DEPTH_LEVELS_M
        self._last_depths: NDArray[np.float32] | None = None

    def follow(self, depths_m: NDArray[np.float32]) -> None:
        """A new frame's measured depths: the range follows them when Auto is on."""
        self._last_depths = depths_m
        if self.auto.isChecked():
            levels = auto_levels_m(depths_m)
            if levels is not None:
                self._set(round(levels[0], 2), round(levels[1], 2))

    def show_histogram(self, depths_m: NDArray[np.float32]) -> None:
        edges, counts = depth_histogram(depths_m, HISTOGRAM_RANGE_M)
        self.curve.setData(edges, counts.astype(float))

    def _set(self, low_m: float, high_m: float) -> None:
        """Show and announce the range (no echo from the widgets' own signals)."""
        if (low_m, high_m) == self.levels_m:
            return
        self.levels_m = (low_m, high_m)
        for widget, value in ((self.low_m, low_m), (self.high_m, high_m)):
            widget.blockSignals(True)
            widget.setValue(value)
            widget.blockSignals(False)
        self.band.blockSignals(True)
        self.band.setRegion((low_m, high_m))
        self.band.blockSignals(False)
        self.levels_changed.emit(low_m, high_m)

    def set_manual(self, low_m: float, high_m: float) -> None:
        """The operator's range: Auto goes off and the range stays."""
        if high_m <= low_m:
            return
        self.auto.blockSignals(True)
        self.auto.setChecked(False)
        self.auto.blockSignals(False)
        self._set(low_m, high_m)

    def _typed(self) -> None:
        self.set_manual(self.low_m.value(), self.high_m.value())

    def _dragged(self) -> None:
        low, high = self.band.getRegion()
        self.set_manual(round(float(low), 2), round(float(high), 2))

    def _auto_toggled(self, on: bool) -> None:
        if on and self._last_depths is not None:
            self.follow(self._last_depths)


def _spin(value: float) -> QtWidgets.QDoubleSpinBox:
    spin = QtWidgets.QDoubleSpinBox()
    spin.setRange(0.0, 8.0)
    spin.setSingleStep(0.1)
    spin.setDecimals(2)
    spin.setValue(value)
    return spin
