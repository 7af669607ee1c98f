"""The 3D view of the plot: the global cloud, each plant's id at its top and the ground grid
(``pyqtgraph.opengl``). Clicking near a plant's label selects it; while points are being picked
(the stems of a split), a click picks the point of the given cloud under it instead (the nearest
on screen within a few pixels, in front: :func:`ui.results.scene.pick_on_screen`), and the
picked points are drawn as numbered markers.

OpenGL is not available everywhere (Qt's offscreen platform has none): :func:`gl_available`
tells, and :class:`CloudView` then shows a side view (x against height) drawn with pyqtgraph's
2D plots instead, with the same labels and selection.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Collection

import numpy as np
import pyqtgraph as pg
import pyqtgraph.opengl as gl
from numpy.typing import NDArray
from OpenGL import GL
from PySide6 import QtCore, QtGui, QtWidgets

from ui.results.scene import CloudScene, depth_m, nearest_on_screen, pick_on_screen, project

log = logging.getLogger(__name__)

GRID_SPACING_M = 0.1
SIDE_POINTS = 30_000
MARKER_RGBA = (0.2, 0.9, 1.0, 1.0)
"""Picked points: cyan, apart from the plants' greens and the selection's orange."""
LABEL_STYLE = "color:#ffe650;font-weight:bold;background:transparent"
MARKER_STYLE = "color:#33e6ff;font-weight:bold;background:transparent"


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
    """The plot in 3D (or from the side without OpenGL). ``plant_clicked(id)`` on a click;
    while picking (:meth:`start_picking`), ``point_picked(ndarray (3,))`` instead."""

    plant_clicked = QtCore.Signal(int)
    point_picked = QtCore.Signal(object)
    pick_missed = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.is_3d = gl_available()
        self.view: _GLView | _SideView = _GLView(self) if self.is_3d else _SideView(self)
        self.view.clicked_plant.connect(self.plant_clicked)
        self.view.picked.connect(self.point_picked)
        self.view.missed.connect(self.pick_missed)
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

    def highlight(self, plants: Collection[int]) -> None:
        """Highlight exactly the points of ``plants`` (several at once), the view unmoved."""
        if self.scene is not None:
            self.view.color(self.scene, plants)

    def focus(self, points_m: NDArray[np.float64]) -> None:
        """Turn the view towards ``points_m`` (N, 3) (a plant), close enough to pick on it."""
        if len(points_m):
            self.view.focus(np.asarray(points_m, np.float64))

    def start_picking(self, points_m: NDArray[np.float64]) -> None:
        """From now on a click picks one of ``points_m`` (N, 3) (``point_picked``) instead of
        selecting a plant."""
        self.view.pickable = np.asarray(points_m, np.float64)

    def stop_picking(self) -> None:
        self.view.pickable = None
        self.set_markers(np.zeros((0, 3)))

    @property
    def picking(self) -> bool:
        return self.view.pickable is not None

    def set_markers(self, points_m: NDArray[np.float64]) -> None:
        """Draw ``points_m`` (M, 3) as markers numbered from 1 (the stems picked)."""
        self.view.set_markers(np.asarray(points_m, np.float64).reshape(-1, 3))


class _GLView(QtWidgets.QWidget):
    clicked_plant = QtCore.Signal(int)
    picked = QtCore.Signal(object)
    missed = QtCore.Signal()

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
        self.markers = gl.GLScatterPlotItem(pxMode=True, size=11.0, color=MARKER_RGBA)
        self.markers.setGLOptions({GL.GL_DEPTH_TEST: False, GL.GL_BLEND: False})
        self.markers.setDepthValue(10)  # drawn last, over the plants: never hidden by a leaf
        self.widget.addItem(self.markers)
        self.scene: CloudScene | None = None
        self.pickable: NDArray[np.float64] | None = None

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
        self.color(scene, [] if plant is None else [plant])
        if plant is not None:
            label = scene.label(plant)
            self.widget.setCameraPosition(pos=QtGui.QVector3D(*label.position_m), distance=1.8)

    def color(self, scene: CloudScene, plants: Collection[int]) -> None:
        self.cloud.setData(color=scene.colors_for(plants))

    def focus(self, points_m: NDArray[np.float64]) -> None:
        low, high = points_m.min(axis=0), points_m.max(axis=0)
        size_m = float(np.max(high - low))
        self.widget.setCameraPosition(
            pos=QtGui.QVector3D(*((low + high) / 2)), distance=max(0.5, 2.5 * size_m)
        )

    def set_markers(self, points_m: NDArray[np.float64]) -> None:
        self.markers.setData(pos=points_m)
        self.widget.set_labels(
            [(f"stem {i + 1}", p) for i, p in enumerate(points_m)], MARKER_STYLE, "markers"
        )

    def _clicked(self, x: float, y: float) -> None:
        if self.pickable is not None:
            points = self.pickable
            mvp = self.widget.mvp()
            pixels = project(points, mvp, self.widget.width(), self.widget.height())
            index = pick_on_screen((x, y), pixels, depth_m(points, mvp))
            if index is None:
                self.missed.emit()
            else:
                self.picked.emit(points[index].copy())
            return
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
        self.overlays: dict[str, tuple[list[tuple[str, np.ndarray]], list[QtWidgets.QLabel]]] = {}

    def mvp(self) -> NDArray[np.float64]:
        """(4, 4) the model-view-projection matrix of the view as it is now."""
        viewport = self.getViewport()
        projection = self.projectionMatrix(viewport, viewport)
        return np.array((projection * self.viewMatrix()).copyDataTo(), np.float64).reshape(4, 4)

    def to_screen(self, points_m: np.ndarray) -> np.ndarray:
        """(N, 2) widget pixels of (N, 3) field points; NaN behind the camera."""
        return project(points_m, self.mvp(), self.width(), self.height())

    def set_labels(
        self, labels: list[tuple[str, np.ndarray]], style: str = LABEL_STYLE, group: str = "ids"
    ) -> None:
        """Text at 3D positions (replacing ``group``'s), as child labels kept over their points
        as the view turns (GLTextItem and painting inside paintGL draw nothing on some
        drivers)."""
        for widget in self.overlays.get(group, ([], []))[1]:
            widget.hide()  # at once: a deferred delete waits for the event loop
            widget.deleteLater()
        widgets = []
        for text, _ in labels:
            widget = QtWidgets.QLabel(text, self)
            widget.setStyleSheet(style)
            widget.setAttribute(QtCore.Qt.WidgetAttribute.WA_TransparentForMouseEvents)
            widget.adjustSize()
            widget.show()
            widgets.append(widget)
        self.overlays[group] = (labels, widgets)
        self.update()

    def paintGL(self, *args: object, **kwargs: object) -> None:
        super().paintGL(*args, **kwargs)
        for labels, widgets in self.overlays.values():
            if not labels:
                continue
            pixels = self.to_screen(np.array([position for _, position in labels]))
            for widget, (x, y) in zip(widgets, pixels, strict=True):
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
    picked = QtCore.Signal(object)
    missed = QtCore.Signal()

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
        marker_rgb = [round(255 * c) for c in MARKER_RGBA[:3]]
        self.markers = pg.ScatterPlotItem(
            size=11, symbol="o", pen=pg.mkPen("k"), brush=pg.mkBrush(*marker_rgb)
        )
        self.markers.setZValue(10)
        self.addItem(self.markers)
        self.texts: list[pg.TextItem] = []
        self.marker_texts: list[pg.TextItem] = []
        self.scene_data: CloudScene | None = None
        self.pickable: NDArray[np.float64] | None = None
        self.scene().sigMouseClicked.connect(self._clicked)

    def show_scene(self, scene: CloudScene | None) -> None:
        self.scene_data = scene
        for text in self.texts:
            self.removeItem(text)
        self.texts = []
        if scene is None:
            self.scatter.clear()
            return
        self._draw_points(scene, [])
        x0, x1 = scene.extent_m[:2]
        self.ground.setData([x0, x1], [0.0, 0.0])
        for label in scene.labels:
            text = pg.TextItem(str(label.plant), color=(200, 150, 0), anchor=(0.5, 1.0))
            text.setPos(float(label.position_m[0]), float(label.position_m[2]))
            self.addItem(text)
            self.texts.append(text)

    def select(self, scene: CloudScene, plant: int | None) -> None:
        self._draw_points(scene, [] if plant is None else [plant])

    def color(self, scene: CloudScene, plants: Collection[int]) -> None:
        self._draw_points(scene, plants)

    def focus(self, points_m: NDArray[np.float64]) -> None:
        low, high = points_m.min(axis=0), points_m.max(axis=0)
        self.setRange(xRange=(low[0], high[0]), yRange=(min(0.0, low[2]), high[2]), padding=0.15)

    def set_markers(self, points_m: NDArray[np.float64]) -> None:
        self.markers.setData(x=points_m[:, 0], y=points_m[:, 2])
        for text in self.marker_texts:
            self.removeItem(text)
        self.marker_texts = []
        for i, point in enumerate(points_m):
            text = pg.TextItem(f"stem {i + 1}", color=(50, 230, 255), anchor=(0.5, 1.2))
            text.setPos(float(point[0]), float(point[2]))
            self.addItem(text)
            self.marker_texts.append(text)

    def _draw_points(self, scene: CloudScene, plants: Collection[int]) -> None:
        """Every point in one colour, the selected plants' over them in the highlight colour
        (one brush per item: per-point brush lists, replaced, crash PySide6 6.12)."""
        step = max(1, len(scene.points_m) // SIDE_POINTS)
        points = scene.points_m[::step]
        self.scatter.setData(x=points[:, 0], y=points[:, 2])
        mine = scene.points_m[np.isin(scene.plant_of_point, list(plants))]
        self.selected.setData(x=mine[:, 0], y=mine[:, 2])

    def _clicked(self, event: object) -> None:
        position = self.plotItem.vb.mapSceneToView(event.scenePos())  # type: ignore[attr-defined]
        if self.pickable is not None:
            self._pick(position.x(), position.y())
            return
        if self.scene_data is None:
            return
        best = None
        for label in self.scene_data.labels:
            distance = abs(float(label.position_m[0]) - position.x())
            if distance <= max(label.radius_m, 0.05) and (best is None or distance < best[0]):
                best = (distance, label.plant)
        if best is not None:
            self.clicked_plant.emit(best[1])

    def _pick(self, x_m: float, z_m: float) -> None:
        """Pick the point drawn nearest (x, height) on screen; the side view looks along +y,
        so the points of smallest y are in front."""
        points = self.pickable
        if points is None:
            return
        pixel_x_m, pixel_z_m = self.plotItem.vb.viewPixelSize()
        pixels = np.c_[(points[:, 0] - x_m) / pixel_x_m, (z_m - points[:, 2]) / pixel_z_m]
        index = pick_on_screen((0.0, 0.0), pixels, points[:, 1] - points[:, 1].min())
        if index is None:
            self.missed.emit()
        else:
            self.picked.emit(points[index].copy())
