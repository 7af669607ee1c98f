"""The per-plant inspector: the selected plant alone in 3D, its points coloured by organ (the
stem one colour, each leaf its own), its height line and width circle drawn with their
definitions named, and its leaves (``leaves.csv``) beside it. Selecting a leaf row highlights
that leaf. ``plant_selected(id)`` when the plant is picked here, so that the panel selects it
in the plant table, the 3D view and the map too.

Without OpenGL (Qt's offscreen platform) the plant is drawn from the side (x against height)
with the same colours, lines and highlight, as :class:`ui.results.view3d.CloudView` does.
A plant's drawing is built on the GUI thread: a plant's PLY holds a few thousand points and
reads, with its circle and top, in a few milliseconds (docs/GUI.md).
"""

from __future__ import annotations

import logging

import numpy as np
import pyqtgraph as pg
import pyqtgraph.opengl as gl
from PySide6 import QtCore, QtGui, QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.recon.settings import PlantSettings
from ui.results.data import PlotResults
from ui.results.plant_drawing import PlantDrawing, plant_drawing
from ui.results.tables import leaf_model
from ui.results.view3d import gl_available

log = logging.getLogger(__name__)

HEIGHT_RGBA = (1.0, 0.9, 0.2, 1.0)
WIDTH_RGBA = (0.2, 0.9, 1.0, 1.0)


class PlantInspector(QtWidgets.QWidget):
    """One plant in detail. ``plant_selected(int)``: a plant picked in the inspector's list."""

    plant_selected = QtCore.Signal(int)

    def __init__(
        self, settings: PlantSettings | None = None, parent: QtWidgets.QWidget | None = None
    ) -> None:
        """``settings``: the reconstruction's plant settings (the height's top support)."""
        super().__init__(parent)
        self.settings = settings or PlantSettings()
        self.results: PlotResults | None = None
        self.drawing: PlantDrawing | None = None
        self.highlighted_leaf: int | None = None
        self.plants = QtWidgets.QComboBox()
        self.plants.currentIndexChanged.connect(self._picked)
        self.caption = QtWidgets.QLabel("Select a plant: in the table, the 3D view, the map.")
        self.caption.setWordWrap(True)
        self.is_3d = gl_available()
        self.view: _GLPlantView | _SidePlantView = (
            _GLPlantView(self) if self.is_3d else _SidePlantView(self)
        )
        self.leaves = QtWidgets.QTableView()
        self.leaves.verticalHeader().hide()
        self.leaves.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.leaves.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.SingleSelection)
        self._set_leaves([])
        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel("Plant"))
        top.addWidget(self.plants)
        top.addWidget(self.caption, 1)
        splitter = QtWidgets.QSplitter()
        splitter.addWidget(self.view)
        splitter.addWidget(self.leaves)
        splitter.setStretchFactor(0, 3)
        splitter.setStretchFactor(1, 2)
        splitter.setSizes([540, 460])
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(splitter, 1)

    def set_results(self, results: PlotResults) -> None:
        """A new plot: its plants listed, none shown until one is selected."""
        self.results, self.drawing = results, None
        self.plants.blockSignals(True)
        self.plants.clear()
        self.plants.addItem("-", None)
        for record in results.plants:
            self.plants.addItem(str(record.plant), record.plant)
        self.plants.blockSignals(False)
        self._show(None)

    def show_plant(self, plant: int | None) -> None:
        """Show ``plant`` (None: none); a plant that cannot be drawn says why in the caption."""
        if self.results is None or (self.drawing and self.drawing.plant == plant):
            return
        self.plants.blockSignals(True)
        self.plants.setCurrentIndex(max(0, self.plants.findData(plant)))
        self.plants.blockSignals(False)
        drawing = None
        if plant is not None:
            try:
                drawing = plant_drawing(self.results, plant, self.settings)
            except (FieldappError, KeyError) as error:
                self._show(None)
                self.caption.setText(f"⚠ plant {plant} cannot be drawn: {error}")
                return
        self._show(drawing)

    def select_leaf(self, leaf_id: int | None) -> None:
        """Highlight leaf ``leaf_id`` of the plant shown (None: every leaf) and select its row."""
        if self.drawing is None:
            return
        self.highlighted_leaf = leaf_id
        self.view.color(self.drawing, leaf_id)
        ids = [int(row["leaf_id"]) for row in self.drawing.leaves]
        if leaf_id in ids:
            self.leaves.selectRow(ids.index(leaf_id))
        else:
            self.leaves.clearSelection()

    def _show(self, drawing: PlantDrawing | None) -> None:
        self.drawing, self.highlighted_leaf = drawing, None
        self.view.show_plant(drawing)
        self._set_leaves(drawing.leaves if drawing else [])
        self.caption.setText(
            drawing.caption if drawing else "Select a plant: in the table, the 3D view, the map."
        )

    def _set_leaves(self, leaves: list[dict[str, object]]) -> None:
        self.leaves.setModel(leaf_model(leaves))
        self.leaves.resizeColumnsToContents()
        self.leaves.selectionModel().selectionChanged.connect(self._leaf_row_selected)

    def _leaf_row_selected(self) -> None:
        rows = self.leaves.selectionModel().selectedRows()
        if self.drawing is None or not rows:
            return
        leaf_id = int(self.drawing.leaves[rows[0].row()]["leaf_id"])
        if leaf_id != self.highlighted_leaf:
            self.select_leaf(leaf_id)

    def _picked(self, index: int) -> None:
        plant = self.plants.itemData(index)
        self.show_plant(plant)
        if plant is not None:
            self.plant_selected.emit(int(plant))


class _GLPlantView(gl.GLViewWidget):  # type: ignore[misc]
    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setBackgroundColor((20, 22, 26))
        self.cloud = gl.GLScatterPlotItem(pxMode=True, size=4.0, glOptions="opaque")
        self.height_line = gl.GLLinePlotItem(color=HEIGHT_RGBA, width=3.0, antialias=True)
        self.width_circle = gl.GLLinePlotItem(color=WIDTH_RGBA, width=2.0, antialias=True)
        self.grid = gl.GLGridItem(color=(255, 255, 255, 50))
        for item in (self.grid, self.cloud, self.height_line, self.width_circle):
            self.addItem(item)

    def show_plant(self, drawing: PlantDrawing | None) -> None:
        if drawing is None:
            self.cloud.setData(pos=np.zeros((0, 3)), color=np.zeros((0, 4)))
            for line in (self.height_line, self.width_circle):
                line.setData(pos=np.zeros((0, 3)))
            return
        self.cloud.setData(pos=drawing.points_m, color=drawing.colors)
        self.height_line.setData(pos=drawing.height_line_m)
        self.width_circle.setData(pos=drawing.width_circle_m)
        ground = drawing.width_circle_m[0, 2]
        size = max(drawing.width_cm, drawing.height_cm) / 100.0
        self.grid.resetTransform()
        self.grid.setSize(x=1.2 * size, y=1.2 * size)
        self.grid.setSpacing(x=0.05, y=0.05)
        foot = drawing.height_line_m[0]
        self.grid.translate(float(foot[0]), float(foot[1]), float(ground))
        middle = float(ground) + 0.45 * drawing.height_cm / 100.0
        centre = QtGui.QVector3D(float(foot[0]), float(foot[1]), middle)
        self.setCameraPosition(
            pos=centre, distance=1.5 * size, elevation=18, azimuth=drawing.view_azimuth_deg
        )

    def color(self, drawing: PlantDrawing, leaf_id: int | None) -> None:
        self.cloud.setData(color=drawing.colors_for_leaf(leaf_id))


class _SidePlantView(pg.PlotWidget):  # type: ignore[misc]
    """The plant from the side, across its leaves (horizontal: along the direction the
    leaves spread most, from the foot; vertical: height). One scatter per organ instance, each
    with one brush (per-point brush lists, replaced, crash PySide6 6.12)."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setLabel("bottom", "along the leaves, from the foot (m)")
        self.setLabel("left", "height (m)")
        self.setAspectLocked(True)
        self.groups: dict[tuple[int, int], pg.ScatterPlotItem] = {}
        self.height_line = pg.PlotDataItem(pen=pg.mkPen(_rgb255(HEIGHT_RGBA), width=2))
        self.width_segment = pg.PlotDataItem(pen=pg.mkPen(_rgb255(WIDTH_RGBA), width=2))
        self.addItem(self.height_line)
        self.addItem(self.width_segment)

    def show_plant(self, drawing: PlantDrawing | None) -> None:
        for item in self.groups.values():
            self.removeItem(item)
        self.groups = {}
        if drawing is None:
            self.height_line.setData([], [])
            self.width_segment.setData([], [])
            return
        keys = np.c_[drawing.organ, drawing.leaf_id]
        for organ, leaf in np.unique(keys, axis=0):
            mine = (drawing.organ == organ) & (drawing.leaf_id == leaf)
            item = pg.ScatterPlotItem(size=3, pen=None)
            points = drawing.points_m[mine]
            item.setData(x=drawing.along_fan_m(points), y=points[:, 2])
            self.addItem(item)
            self.groups[(int(organ), int(leaf))] = item
        self.height_line.setData([0.0, 0.0], drawing.height_line_m[:, 2])
        centre = drawing.along_fan_m(drawing.width_circle_m[:-1].mean(axis=0, keepdims=True))[0]
        radius = drawing.width_cm / 200.0
        ground = drawing.width_circle_m[0, 2]
        self.width_segment.setData([centre - radius, centre + radius], [ground, ground])
        self.color(drawing, None)

    def color(self, drawing: PlantDrawing, leaf_id: int | None) -> None:
        colors = drawing.colors_for_leaf(leaf_id)
        for (organ, leaf), item in self.groups.items():
            first = int(np.flatnonzero((drawing.organ == organ) & (drawing.leaf_id == leaf))[0])
            item.setBrush(pg.mkBrush(_rgb255(tuple(colors[first]))))


def _rgb255(rgba: tuple[float, ...]) -> tuple[int, ...]:
    return tuple(round(255 * c) for c in rgba)
