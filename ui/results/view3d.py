"""The 3D view of the plot: the global cloud, each plant's id at its top and the ground grid
(``pyqtgraph.opengl``). Clicking near a plant's label selects it.

OpenGL is not available everywhere (Qt's offscreen platform has none): :func:`gl_available`
tells, and :class:`CloudView` then shows a side view (x against height) drawn with pyqtgraph's
2D plots instead, with the same labels and selection.
"""

from __future__ import annotations

import functools
import logging

import numpy as np
import pyqtgraph as pg
import pyqtgraph.opengl as gl
from PySide6 import QtCore, QtGui, QtWidgets

from ui.results.scene import CloudScene, nearest_on_screen, project

log = logging.getLogger(__name__)

GRID_SPACING_M = 0.1
SIDE_POINTS = 30_000


@functools.cache
def gl_available() -> bool:
    """Whether an OpenGL context can be made (False on the offscreen platform)."""
    context = QtGui.QOpenGLContext()
    available = bool(context.create())
    if not available:
        log.info(
            "no OpenGL on platform %s: the 3D view falls back to a side view",
            QtGui.QGuiApplication.platformName(),
        )
    return available


class CloudView(QtWidgets.QWidget):
    """The plot in 3D (or from the side without OpenGL). ``plant_clicked(id)`` on a click."""

    plant_clicked = QtCore.Signal(int)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.is_3d = gl_available()
        self.view: _GLView | _SideView = _GLView(self) if self.is_3d else _SideView(self)
        self.view.clicked_plant.connect(self.plant_clicked)
        if not self.is_3d:
            note = QtWidgets.QLabel("No OpenGL here: side view (x against height).")
            note.setObjectName("fallbackNote")
            layout.addWidget(note)
        layout.addWidget(self.view)
        self.scene: CloudScene | None = None
        self.selected: int | None = None

    def show_scene(self, scene: CloudScene | None) -> None:
        self.scene, self.selected = scene, None
        self.view.show_scene(scene)

    def select(self, plant: int | None) -> None:
        """Highlight ``plant`` (None: none) and turn the view towards it."""
        if self.scene is None or plant == self.selected:
            return
        self.selected = plant
        self.view.select(self.scene, plant)


class _GLView(QtWidgets.QWidget):
    clicked_plant = QtCore.Signal(int)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.widget = _ClickableGL(self)
        self.widget.setBackgroundColor((20, 22, 26))
        self.widget.clicked.connect(self._clicked)
        layout.addWidget(self.widget)
        self.cloud = gl.GLScatterPlotItem(pxMode=True, size=2.0, glOptions="opaque")
        self.widget.addItem(self.cloud)
        self.grid = gl.GLGridItem(color=(255, 255, 255, 60))
        self.widget.addItem(self.grid)
        self.scene: CloudScene | None = None

    def show_scene(self, scene: CloudScene | None) -> None:
        self.scene = scene
        if scene is None:
            self.cloud.setData(pos=np.zeros((0, 3)), color=np.zeros((0, 4)))
            self.widget.set_labels([])
            return
        self.cloud.setData(pos=scene.points_m, color=scene.colors)
        x0, x1, y0, y1 = scene.extent_m
        self.grid.setSize(x=x1 - x0, y=y1 - y0)
        self.grid.setSpacing(x=GRID_SPACING_M, y=GRID_SPACING_M)
        self.grid.resetTransform()
        self.grid.translate((x0 + x1) / 2, (y0 + y1) / 2, 0.0)
        self.widget.set_labels([(str(label.plant), label.position_m) for label in scene.labels])
        centre = QtGui.QVector3D((x0 + x1) / 2, (y0 + y1) / 2, 0.0)
        self.widget.setCameraPosition(
            pos=centre, distance=1.4 * max(x1 - x0, y1 - y0), elevation=35, azimuth=-60
        )

    def select(self, scene: CloudScene, plant: int | None) -> None:
        self.cloud.setData(color=scene.colors_for(plant))
        if plant is not None:
            label = scene.label(plant)
            self.widget.setCameraPosition(pos=QtGui.QVector3D(*label.position_m), distance=1.8)

    def _clicked(self, x: float, y: float) -> None:
        if self.scene is None or not self.scene.labels:
            return
        positions = np.array([label.position_m for label in self.scene.labels])
        pixels = self.widget.to_screen(positions)
        projected = [
            (label.plant, float(px), float(py))
            for label, (px, py) in zip(self.scene.labels, pixels, strict=True)
            if np.isfinite(px)
        ]
        plant = nearest_on_screen((x, y), projected)
        if plant is not None:
            self.clicked_plant.emit(plant)


class _ClickableGL(gl.GLViewWidget):  # type: ignore[misc]
    """A GLViewWidget that reports a click (press and release without a drag) and paints
    text labels over the scene at 3D positions (GLTextItem draws nothing on some drivers)."""

    clicked = QtCore.Signal(float, float)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.labels: list[tuple[str, np.ndarray]] = []
        self._label_widgets: list[QtWidgets.QLabel] = []

    def to_screen(self, points_m: np.ndarray) -> np.ndarray:
        """(N, 2) widget pixels of (N, 3) field points; NaN behind the camera."""
        viewport = self.getViewport()
        projection = self.projectionMatrix(viewport, viewport)
        mvp = np.array((projection * self.viewMatrix()).copyDataTo()).reshape(4, 4)
        return project(points_m, mvp, self.width(), self.height())

    def set_labels(self, labels: list[tuple[str, np.ndarray]]) -> None:
        """Text at 3D positions, as child labels kept over their points as the view turns
        (GLTextItem and painting inside paintGL draw nothing on some drivers)."""
        for widget in self._label_widgets:
            widget.deleteLater()
        self.labels = labels
        self._label_widgets = []
        for text, _ in labels:
            widget = QtWidgets.QLabel(text, self)
            widget.setStyleSheet("color:#ffe650;font-weight:bold;background:transparent")
            widget.setAttribute(QtCore.Qt.WidgetAttribute.WA_TransparentForMouseEvents)
            widget.adjustSize()
            widget.show()
            self._label_widgets.append(widget)
        self.update()

    def paintGL(self, *args: object, **kwargs: object) -> None:
        super().paintGL(*args, **kwargs)
        if not self.labels:
            return
        pixels = self.to_screen(np.array([position for _, position in self.labels]))
        for widget, (x, y) in zip(self._label_widgets, pixels, strict=True):
            visible = bool(np.isfinite(x) and np.isfinite(y))
            widget.setVisible(visible)
            if visible:
                widget.move(round(x) - widget.width() // 2, round(y) - widget.height())

    def mousePressEvent(self, event: QtGui.QMouseEvent) -> None:
        self._pressed_at = event.position()
        super().mousePressEvent(event)

    def mouseReleaseEvent(self, event: QtGui.QMouseEvent) -> None:
        pressed = getattr(self, "_pressed_at", None)
        if pressed is not None and (event.position() - pressed).manhattanLength() < 4:
            self.clicked.emit(event.position().x(), event.position().y())
        super().mouseReleaseEvent(event)


class _SideView(pg.PlotWidget):  # type: ignore[misc]
    clicked_plant = QtCore.Signal(int)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setLabel("bottom", "x (m, field frame)")
        self.setLabel("left", "height (m)")
        self.setAspectLocked(True)
        self.scatter = pg.ScatterPlotItem(size=2, pen=None, brush=pg.mkBrush(70, 150, 70, 160))
        self.addItem(self.scatter)
        self.selected = pg.ScatterPlotItem(size=3, pen=None, brush=pg.mkBrush(255, 90, 30))
        self.addItem(self.selected)
        self.ground = pg.PlotDataItem(pen=pg.mkPen((120, 120, 120), width=1))
        self.addItem(self.ground)
        self.texts: list[pg.TextItem] = []
        self.scene_data: CloudScene | None = None
        self.scene().sigMouseClicked.connect(self._clicked)

    def show_scene(self, scene: CloudScene | None) -> None:
        self.scene_data = scene
        for text in self.texts:
            self.removeItem(text)
        self.texts = []
        if scene is None:
            self.scatter.clear()
            return
        self._draw_points(scene, None)
        x0, x1 = scene.extent_m[:2]
        self.ground.setData([x0, x1], [0.0, 0.0])
        for label in scene.labels:
            text = pg.TextItem(str(label.plant), color=(200, 150, 0), anchor=(0.5, 1.0))
            text.setPos(float(label.position_m[0]), float(label.position_m[2]))
            self.addItem(text)
            self.texts.append(text)

    def select(self, scene: CloudScene, plant: int | None) -> None:
        self._draw_points(scene, plant)

    def _draw_points(self, scene: CloudScene, plant: int | None) -> None:
        """Every point in one colour, the selected plant's over them in the highlight colour
        (one brush per item: per-point brush lists, replaced, crash PySide6 6.12)."""
        step = max(1, len(scene.points_m) // SIDE_POINTS)
        points = scene.points_m[::step]
        self.scatter.setData(x=points[:, 0], y=points[:, 2])
        mine = scene.points_m[scene.plant_of_point == plant] if plant is not None else points[:0]
        self.selected.setData(x=mine[:, 0], y=mine[:, 2])

    def _clicked(self, event: object) -> None:
        if self.scene_data is None:
            return
        position = self.plotItem.vb.mapSceneToView(event.scenePos())  # type: ignore[attr-defined]
        best = None
        for label in self.scene_data.labels:
            distance = abs(float(label.position_m[0]) - position.x())
            if distance <= max(label.radius_m, 0.05) and (best is None or distance < best[0]):
                best = (distance, label.plant)
        if best is not None:
            self.clicked_plant.emit(best[1])
