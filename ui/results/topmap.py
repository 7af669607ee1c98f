"""The top-down map of the plot: the cloud from above, each plant's base, id and width (the
circle enclosing its projection). Clicking a plant selects it; while picking (the stems of a
split) a click gives its position instead, and the picked positions are drawn as markers."""

from __future__ import annotations

from collections.abc import Collection

import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from ui.results.scene import CloudScene, nearest_plant

MAP_POINTS = 40_000
NORMAL_PEN = pg.mkPen((230, 60, 40), width=1.5)
SELECTED_PEN = pg.mkPen((255, 200, 0), width=3.5)


class TopMap(pg.PlotWidget):  # type: ignore[misc]
    """``plant_clicked(id)`` when a click lands on (or near) a plant; while ``picking``,
    ``point_clicked(x_m, y_m)`` instead."""

    plant_clicked = QtCore.Signal(int)
    point_clicked = QtCore.Signal(float, float)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setAspectLocked(True)
        self.setLabel("bottom", "x (m, field frame)")
        self.setLabel("left", "y (m, field frame)")
        self.showGrid(x=True, y=True, alpha=0.25)
        self.points = pg.ScatterPlotItem(size=2, pen=None, brush=pg.mkBrush(60, 140, 60, 160))
        self.addItem(self.points)
        self.circles: dict[int, QtWidgets.QGraphicsEllipseItem] = {}
        self.texts: list[pg.TextItem] = []
        self.markers = pg.ScatterPlotItem(
            size=12, symbol="+", pen=pg.mkPen((50, 230, 255), width=2.5), brush=None
        )
        self.markers.setZValue(10)
        self.addItem(self.markers)
        self.scene_data: CloudScene | None = None
        self.selected: int | None = None
        self.highlighted: set[int] = set()
        self.picking = False
        self.scene().sigMouseClicked.connect(self._clicked)

    def show_scene(self, scene: CloudScene | None) -> None:
        for item in [*self.circles.values(), *self.texts]:
            self.removeItem(item)
        self.circles, self.texts, self.selected, self.highlighted = {}, [], None, set()
        self.scene_data = scene
        if scene is None:
            self.points.clear()
            return
        step = max(1, len(scene.points_m) // MAP_POINTS)
        self.points.setData(x=scene.points_m[::step, 0], y=scene.points_m[::step, 1])
        for label in scene.labels:
            x, y, r = float(label.position_m[0]), float(label.position_m[1]), label.radius_m
            circle = QtWidgets.QGraphicsEllipseItem(x - r, y - r, 2 * r, 2 * r)
            circle.setPen(NORMAL_PEN)
            self.addItem(circle)
            self.circles[label.plant] = circle
            text = pg.TextItem(str(label.plant), color=(255, 90, 60), anchor=(0, 1))
            text.setPos(x + r * 0.7, y + r * 0.7)
            self.addItem(text)
            self.texts.append(text)
        self.autoRange()

    def select(self, plant: int | None) -> None:
        if plant == self.selected:
            return
        self.selected = plant
        self.highlight([] if plant is None else [plant])

    def highlight(self, plants: Collection[int]) -> None:
        """Draw the circles of ``plants`` (several at once) in the selection's pen."""
        self.highlighted = set(plants)
        for plant, circle in self.circles.items():
            circle.setPen(SELECTED_PEN if plant in self.highlighted else NORMAL_PEN)

    def set_markers(self, points_xy_m: list[tuple[float, float]]) -> None:
        """Mark ``points_xy_m`` (the stems picked)."""
        self.markers.setData(pos=[(float(x), float(y)) for x, y in points_xy_m])

    def _clicked(self, event: object) -> None:
        position = self.plotItem.vb.mapSceneToView(event.scenePos())  # type: ignore[attr-defined]
        if self.picking:
            self.point_clicked.emit(position.x(), position.y())
            return
        if self.scene_data is None:
            return
        plant = nearest_plant((position.x(), position.y()), self.scene_data.labels, 0.1)
        if plant is not None:
            self.plant_clicked.emit(plant)
