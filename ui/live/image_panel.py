"""The Live page's images: depth (colour-mapped, with its colour bar) beside or above the
colour or IR image, whichever arrangement shows them larger in the panel's shape, on the
window's background (no black margins around the images); the two picked points of a
distance measurement marked on both."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6 import QtCore, QtGui

from ui.live.frame_math import best_arrangement, depth_indices, depth_lut

DEPTH_LEVELS_M = (0.5, 4.5)
KINECT_SIZE = (512, 424)
"""Image (w, h) assumed until the first frame arrives."""
BAR_W = 90
"""Width the colour bar and the layout's spacing take from the images (pixels)."""
MARK_COLOUR = (255, 0, 255)


class ImagePanel(pg.GraphicsLayoutWidget):  # type: ignore[misc]  # pyqtgraph is untyped
    """Depth beside (or above) colour or IR; :attr:`arrangement` is ``"row"`` or
    ``"column"``."""

    def __init__(self) -> None:
        super().__init__()
        self.setBackground(self.palette().color(QtGui.QPalette.ColorRole.Window))
        self.ci.setContentsMargins(0, 0, 0, 0)
        self.ci.setSpacing(2)
        self.depth_plot = self.addPlot(row=0, col=0, title="Depth (m)")
        self.second_plot = self.addPlot(row=0, col=2, title="Colour")
        self.depth_item = pg.ImageItem(axisOrder="row-major")
        self.second_item = pg.ImageItem(axisOrder="row-major")
        self.marks: list[tuple[pg.ScatterPlotItem, pg.PlotCurveItem]] = []
        for plot, item in (
            (self.depth_plot, self.depth_item),
            (self.second_plot, self.second_item),
        ):
            _bare(plot)
            plot.addItem(item)
            self.marks.append(_marks(plot))
        # not linked: linked views with locked aspects feed each other's range until it is
        # many times the image (the images then shrink to a corner); each frames its own
        colour_map = pg.colormap.get("turbo")
        self.colour_bar = pg.ColorBarItem(
            values=DEPTH_LEVELS_M, colorMap=colour_map, interactive=False, label="depth (m)",
            colorMapMenu=False,
        )  # fmt: skip
        self.addItem(self.colour_bar, row=0, col=1)
        lut = colour_map.getLookupTable(nPts=255, alpha=False)
        self.depth_item.setLookupTable(depth_lut(lut))
        self.levels_m: tuple[float, float] = DEPTH_LEVELS_M
        self.depth_m: NDArray[np.float32] | None = None
        self.arrangement = "row"
        self.second_shown = True

    def show_depth(self, depth_m: NDArray[np.float32]) -> None:
        """Depth colour-mapped between the levels (black where missing)."""
        self.depth_m = depth_m
        self.depth_item.setImage(depth_indices(depth_m, *self.levels_m), levels=(0, 255))

    def fit(self) -> None:
        """Frame the whole image, and keep framing it as the panel is resized."""
        for plot in (self.depth_plot, self.second_plot):
            plot.getViewBox().setDefaultPadding(0.0)
        width, height = self.image_size()
        self.depth_plot.getViewBox().setRange(QtCore.QRectF(0.0, 0.0, width, height), padding=0.0)
        self.depth_plot.enableAutoRange()
        self.arrange()

    def set_levels(self, low_m: float, high_m: float) -> None:
        if (low_m, high_m) == self.levels_m:
            return
        self.levels_m = (low_m, high_m)
        self.colour_bar.setLevels((low_m, high_m))
        if self.depth_m is not None:
            self.show_depth(self.depth_m)

    def show_second(self, kind: str) -> None:
        visible = kind != "None"
        self.second_shown = visible
        self.second_plot.setVisible(visible)
        self.second_plot.setTitle(kind if visible else "")
        self.arrange()

    def show_marks(self, pixels: list[tuple[int, int]]) -> None:
        """Mark the picked pixels (u, v) on both images, joined by a line when two."""
        xs = np.array([u + 0.5 for u, _ in pixels], float)
        ys = np.array([v + 0.5 for _, v in pixels], float)
        for scatter, line in self.marks:
            scatter.setData(xs, ys)
            line.setData(xs if len(pixels) == 2 else [], ys if len(pixels) == 2 else [])

    def image_size(self) -> tuple[int, int]:
        if self.depth_m is None:
            return KINECT_SIZE
        height, width = self.depth_m.shape
        return width, height

    def arrange(self) -> None:
        """Put the second image beside or below the depth, whichever shows both larger."""
        count = 2 if self.second_shown else 1
        area = (max(self.width() - BAR_W, 1), max(self.height(), 1))
        kind, _scale = best_arrangement(area, self.image_size(), count)
        if kind == self.arrangement:
            self._share_space()
            return
        self.ci.removeItem(self.second_plot)
        row, col = (0, 2) if kind == "row" else (1, 0)
        self.ci.addItem(self.second_plot, row=row, col=col)
        self.arrangement = kind
        self._share_space()

    def _share_space(self) -> None:
        """The two images' cells equally wide side by side (the colour bar keeps its own
        width); the grid would otherwise give the second cell what the bar leaves over."""
        grid = self.ci.layout
        if self.arrangement == "row" and self.second_shown:
            cell = max((self.width() - BAR_W) / 2, 1.0)
            for col in (0, 2):
                grid.setColumnMinimumWidth(col, cell)
                grid.setColumnMaximumWidth(col, cell)
        else:
            for col in (0, 2):
                grid.setColumnMinimumWidth(col, 0.0)
                grid.setColumnMaximumWidth(col, 1e6)

    def resizeEvent(self, event: QtGui.QResizeEvent | None) -> None:
        super().resizeEvent(event)
        # the base class resizes while being built, and after close() (its scene cleared)
        if hasattr(self, "second_plot") and not getattr(self, "closed", False):
            self.arrange()


def _bare(plot: pg.PlotItem) -> None:
    """An image plot without axes, buttons or menu, pixels square, rows downwards."""
    plot.setAspectLocked(True)
    plot.invertY(True)
    plot.hideButtons()
    plot.hideAxis("left")
    plot.hideAxis("bottom")
    plot.setMenuEnabled(False)


def _marks(plot: pg.PlotItem) -> tuple[pg.ScatterPlotItem, pg.PlotCurveItem]:
    line = pg.PlotCurveItem(pen=pg.mkPen(MARK_COLOUR, width=2))
    scatter = pg.ScatterPlotItem(
        size=11, pen=pg.mkPen("w", width=1.5), brush=pg.mkBrush(*MARK_COLOUR), symbol="o"
    )
    for item in (line, scatter):
        item.setZValue(10)
        plot.addItem(item)
    return scatter, line
