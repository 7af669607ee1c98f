"""A rotatable 3D view of the current frame's points (pyqtgraph's OpenGL items).

OpenGL may be missing (a remote display, the offscreen platform of the tests): the view then
says so in a label and the rest of the preview works as before.
"""

from __future__ import annotations

import logging
from functools import cache

from PySide6 import QtCore, QtGui, QtWidgets

from devices.camera.frames import Frame, Intrinsics
from ui.live.frame_math import cloud_points

log = logging.getLogger(__name__)


@cache
def opengl_problem() -> str | None:
    """Why OpenGL cannot be used on this display, or ``None`` when it can."""
    try:
        import OpenGL.GL  # noqa: F401
    except ImportError as error:
        return f"PyOpenGL is not installed ({error})"
    from PySide6.QtOpenGL import QOpenGLFramebufferObject

    platform = QtGui.QGuiApplication.platformName()
    if platform in ("offscreen", "minimal"):  # no widget can render OpenGL there
        return f"the '{platform}' display has no OpenGL widgets"
    context = QtGui.QOpenGLContext()
    if not context.create():
        return f"no OpenGL context on the '{platform}' display"
    surface = QtGui.QOffscreenSurface()
    surface.setFormat(context.format())
    surface.create()
    try:
        if not context.makeCurrent(surface):
            return f"OpenGL context cannot be made current on the '{platform}' display"
        framebuffer = QOpenGLFramebufferObject(16, 16)  # what QOpenGLWidget renders into
        usable = framebuffer.isValid()
        del framebuffer
        context.doneCurrent()
    finally:
        surface.destroy()
    return None if usable else f"no OpenGL framebuffer on the '{platform}' display"


class CloudView(QtWidgets.QWidget):
    """The points of one frame, coloured by the registered colour image; drag to rotate."""

    def __init__(self, parent: QtWidgets.QWidget | None = None, step: int = 4) -> None:
        super().__init__(parent)
        self.step = step
        self.points_shown = 0
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.problem = opengl_problem()
        if self.problem is not None:
            self.view = None
            self.scatter = None
            label = QtWidgets.QLabel(f"3D view unavailable: {self.problem}.")
            label.setObjectName("cloudUnavailable")
            label.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
            label.setWordWrap(True)
            layout.addWidget(label)
            return
        import pyqtgraph.opengl as gl

        self.view = gl.GLViewWidget()
        self.view.setBackgroundColor((25, 28, 32))
        self.view.setCameraPosition(distance=4.0, elevation=25.0, azimuth=-90.0)
        self.view.opts["center"] = QtGui.QVector3D(0.0, 2.0, -0.8)
        grid = gl.GLGridItem()
        grid.setSize(6, 6)
        grid.setSpacing(0.5, 0.5)
        grid.translate(0.0, 2.0, -1.3)
        self.view.addItem(grid)
        self.scatter = gl.GLScatterPlotItem(size=2.0, pxMode=True)
        self.view.addItem(self.scatter)
        layout.addWidget(self.view)

    @property
    def available(self) -> bool:
        return self.view is not None

    def show_frame(self, frame: Frame, intrinsics: Intrinsics) -> None:
        points, colours = cloud_points(frame, intrinsics, self.step)
        self.points_shown = len(points)
        if self.scatter is not None:
            self.scatter.setData(pos=points, color=colours)
