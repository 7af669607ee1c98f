"""The pictures users know from the ROS and MATLAB calibrators, on the solve pages:

- intrinsics: each view's reprojection error as a bar (rejected views in red, the overall RMS
  as a line), and the chosen view's image with its detected corners (green circles) and the
  corners reprojected through the solved lens (red crosses; their offsets drawn 10 times
  longer, so a bad view shows at a glance);
- stations: a top view of where each station's camera stands, joined to the station it was
  measured through: in the field frame (z up) when the calibration in force has a ground,
  else the reference camera's x and z (a tilted camera's view, said on the axes).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6 import QtCore, QtGui, QtWidgets

from devices.camera.frames import Intrinsics
from devices.geometry import Matrix4
from fieldapp.calib.board import Board
from fieldapp.calib.intrinsics import IntrinsicsResult
from fieldapp.calib.stations import StationsResult
from ui.calibration.live import drawn, picture_label, to_pixmap

OFFSET_SCALE = 10.0
"""Reprojection offsets are drawn this many times longer than they are."""
USED_BRUSH, REJECTED_BRUSH = (60, 110, 190), (198, 40, 40)

Views = Callable[[], list[tuple[str, NDArray[Any], NDArray[np.float32]]]]
"""The views solved from: (name, image, detected corners (N, 2) float32)."""


def reproject(
    corners: NDArray[np.float32], board: Board, intrinsics: Intrinsics
) -> NDArray[np.float64] | None:
    """(N, 2) pixels: the board's corners reprojected through ``intrinsics`` from the board
    pose that best fits ``corners`` (OpenCV's PnP); ``None`` when no pose fits."""
    K, dist = intrinsics.K, np.asarray(intrinsics.distortion, np.float64)
    objects = board.object_points_m()
    image_points = corners.reshape(-1, 1, 2).astype(np.float64)
    ok, rvec, tvec = cv2.solvePnP(objects, image_points, K, dist)
    if not ok:
        return None
    projected, _ = cv2.projectPoints(objects, rvec, tvec, K, dist)
    result: NDArray[np.float64] = projected.reshape(-1, 2)
    return result


def rms_px(a: NDArray[np.floating[Any]], b: NDArray[np.floating[Any]]) -> float:
    return float(np.sqrt(np.mean(np.sum((a.reshape(-1, 2) - b.reshape(-1, 2)) ** 2, axis=1))))


def overlay(
    image: NDArray[Any],
    corners: NDArray[np.float32],
    reprojected: NDArray[np.float64],
    width_px: int = 640,
) -> NDArray[np.uint8]:
    """(h, ``width_px``, 3) RGB: the board's part of ``image``, enlarged, with the detected
    (green circles) and reprojected (red crosses) corners and their offsets (yellow, x
    :data:`OFFSET_SCALE`)."""
    rgb = drawn(image, None, Board(3, 3, 1.0))  # grey to RGB, nothing drawn yet
    found = corners.reshape(-1, 2).astype(np.float64)
    low, high = found.min(axis=0), found.max(axis=0)
    margin = 0.15 * (high - low).max() + 10
    x0, y0 = np.maximum(np.floor(low - margin), 0).astype(int)
    x1, y1 = np.minimum(np.ceil(high + margin), (rgb.shape[1], rgb.shape[0])).astype(int)
    scale = width_px / max(x1 - x0, 1)
    crop = cv2.resize(rgb[y0:y1, x0:x1], None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR)
    origin = np.array([x0, y0], float)
    for point, projected in zip(found, reprojected, strict=True):
        (u, v), (pu, pv) = (point - origin) * scale, (projected - origin) * scale
        tip = (u + OFFSET_SCALE * (pu - u), v + OFFSET_SCALE * (pv - v))
        cv2.line(crop, _px(u, v), _px(*tip), (255, 200, 0), 2, cv2.LINE_AA)
        cv2.circle(crop, _px(u, v), 6, (40, 200, 60), 2, cv2.LINE_AA)
        cv2.drawMarker(crop, _px(pu, pv), (230, 40, 40), cv2.MARKER_CROSS, 10, 2, cv2.LINE_AA)
    return np.ascontiguousarray(crop)


def _px(u: float, v: float) -> tuple[int, int]:
    return round(float(u)), round(float(v))


class ReprojectionPicture(QtWidgets.QWidget):
    """Per-view error bars and the reprojection overlay of the view chosen below them."""

    def __init__(self, views: Views, board: Callable[[], Board]) -> None:
        super().__init__()
        self.views, self.board = views, board
        self.result: IntrinsicsResult | None = None
        self.errors_px: dict[str, float] = {}
        self.bars = pg.PlotWidget()
        self.bars.setBackground(self.palette().color(QtGui.QPalette.ColorRole.Window))
        self.bars.setLabel("left", "reprojection error (px)")
        self.bars.getAxis("left").enableAutoSIPrefix(False)
        self.bars.setLabel("bottom", "view")
        self.bars.setMouseEnabled(x=False, y=False)
        self.bars.setMenuEnabled(False)
        self.bars.setMinimumHeight(170)
        self.bar_item = pg.BarGraphItem(x=[], height=[], width=0.7)
        self.bars.addItem(self.bar_item)
        self.rms_line = pg.InfiniteLine(
            angle=0, pen=pg.mkPen((0, 0, 0), style=QtCore.Qt.PenStyle.DashLine)
        )
        self.bars.addItem(self.rms_line)
        self.choice = QtWidgets.QComboBox()
        self.choice.currentIndexChanged.connect(self._show_choice)
        self.picture = picture_label("", 360, 260)
        self.caption = QtWidgets.QLabel("")
        self.caption.setWordWrap(True)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Reprojection of"))
        row.addWidget(self.choice, 1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self.bars)
        layout.addLayout(row)
        layout.addWidget(self.picture, 1)
        layout.addWidget(self.caption)

    def show_result(self, result: IntrinsicsResult) -> None:
        self.result = result
        shown = [v for v in result.views if v.error_px is not None]
        self.errors_px = {v.name: float(v.error_px or 0.0) for v in shown}
        brushes = [USED_BRUSH if v.rejected is None else REJECTED_BRUSH for v in shown]
        self.bar_item.setOpts(
            x=np.arange(1, len(shown) + 1), height=list(self.errors_px.values()), brushes=brushes
        )
        self.bars.getAxis("bottom").setTicks([[(i + 1, str(i + 1)) for i in range(len(shown))]])
        self.rms_line.setValue(result.rms_px)
        self.bars.setToolTip(
            "\n".join(f"{i + 1}: {v.name} {v.error_px:.3f} px" for i, v in enumerate(shown))
            + f"\ndashed: RMS {result.rms_px:.3f} px; red: not used"
        )
        self.choice.blockSignals(True)
        self.choice.clear()
        self.choice.addItems([f"{i + 1}: {v.name}" for i, v in enumerate(shown)])
        self.choice.blockSignals(False)
        worst = max(range(len(shown)), key=lambda i: shown[i].error_px or 0.0, default=-1)
        self.choice.setCurrentIndex(worst)  # the worst view first: what to look at
        self._show_choice(worst)

    def reprojection_of(
        self, name: str
    ) -> tuple[NDArray[Any], NDArray[np.float32], NDArray[np.float64]] | None:
        """(image, detected corners, reprojected corners) of the view ``name``."""
        if self.result is None:
            return None
        for view_name, image, corners in self.views():
            if view_name == name:
                reprojected = reproject(corners, self.board(), self.result.intrinsics)
                return None if reprojected is None else (image, corners, reprojected)
        return None

    def _show_choice(self, index: int) -> None:
        names = list(self.errors_px)
        if not 0 <= index < len(names):
            return
        found = self.reprojection_of(names[index])
        if found is None:
            self.picture.setText(f"{names[index]}: no pose fits its corners")
            return
        image, corners, reprojected = found
        pixmap = to_pixmap(overlay(image, corners, reprojected))
        self.picture.setPixmap(
            pixmap.scaled(self.picture.size(), QtCore.Qt.AspectRatioMode.KeepAspectRatio)
        )
        self.caption.setText(
            f"{names[index]}: {rms_px(corners, reprojected):.3f} px RMS. Green circles: corners "
            f"found; red crosses: reprojected; yellow: the offset x {OFFSET_SCALE:.0f}."
        )


class StationLayout(pg.PlotWidget):  # type: ignore[misc]  # pyqtgraph is untyped
    """Top view of the stations' cameras (view 0), each joined to the station it was measured
    through; :attr:`positions` are the plotted (horizontal, vertical) metres per station."""

    def __init__(self) -> None:
        super().__init__()
        self.setBackground(self.palette().color(QtGui.QPalette.ColorRole.Window))
        self.setAspectLocked(True)
        self.showGrid(x=True, y=True, alpha=0.3)
        self.setMenuEnabled(False)
        self.setMinimumSize(320, 300)
        for side in ("left", "bottom"):
            self.getAxis(side).enableAutoSIPrefix(False)
        self.setTitle("Where the stations stand (top view)")
        self.positions: dict[int, tuple[float, float]] = {}

    def show_result(
        self, result: StationsResult, reference: int, T_field_reference: Matrix4 | None = None
    ) -> None:
        """Plot ``result``'s stations; in the field frame (x, y) when ``T_field_reference``
        is given, else the reference camera's (x, z)."""
        self.clear()
        if T_field_reference is not None:
            self.positions = {
                s: (float(p[0]), float(p[1]))
                for s, T in result.T_reference_station.items()
                for p in [(T_field_reference @ T)[:3, 3]]
            }
            self.setLabel("bottom", "field x (m)")
            self.setLabel("left", "field y (m), ground in force")
        else:
            self.positions = {
                s: (float(T[0, 3]), float(T[2, 3])) for s, T in result.T_reference_station.items()
            }
            self.setLabel("bottom", "x: right of the reference camera (m)")
            self.setLabel("left", "z: ahead of it (m), camera not levelled: no ground yet")
        for station, parent in result.tree.items():
            if station in self.positions and parent in self.positions:
                (x0, z0), (x1, z1) = self.positions[station], self.positions[parent]
                self.plot([x0, x1], [z0, z1], pen=pg.mkPen((120, 120, 120), width=2))
        for station, (x, z) in sorted(self.positions.items()):
            is_reference = station == reference
            self.plot(
                [x], [z], symbol="s" if is_reference else "o", symbolSize=14, pen=None,
                symbolBrush=(198, 40, 40) if is_reference else (60, 110, 190),
            )  # fmt: skip
            label = pg.TextItem(
                f"station {station}" + (" (reference)" if is_reference else ""),
                color=(20, 20, 20), anchor=(0.5, 1.3),
            )  # fmt: skip
            label.setPos(x, z)
            self.addItem(label)
        self.getViewBox().autoRange(padding=0.35)  # room for the labels
