"""The plan on a map (the base's map frame, metres): stations numbered in visiting order, the
path between them, the reference station ringed, each station coloured by its progress, and
the base's live pose as an arrow."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui

from fieldapp.mission.plan import MissionPlan

PENDING = "#90a4ae"
ACTIVE = "#ffb300"
DONE = "#43a047"
LOW = "#fb8c00"


def arrow_symbol() -> QtGui.QPainterPath:
    """A triangle pointing along +x (the base's heading at yaw 0)."""
    path = QtGui.QPainterPath()
    path.moveTo(0.5, 0.0)
    path.lineTo(-0.35, 0.3)
    path.lineTo(-0.2, 0.0)
    path.lineTo(-0.35, -0.3)
    path.closeSubpath()
    return path


def rotated(path: QtGui.QPainterPath, yaw_deg: float) -> QtGui.QPainterPath:
    """``path`` turned counter-clockwise by ``yaw_deg`` on the map (y up)."""
    transform = QtGui.QTransform()
    transform.rotate(-yaw_deg)  # scatter symbols are drawn with y down
    return transform.map(path)


class PlanMap(pg.PlotWidget):  # type: ignore[misc]  # pyqtgraph is untyped
    """Stations, path and base pose; :attr:`station_clicked` gives a station number."""

    station_clicked = QtCore.Signal(int)

    def __init__(self) -> None:
        super().__init__()
        self.setBackground("w")
        self.setAspectLocked(True)
        self.showGrid(x=True, y=True, alpha=0.25)
        self.setLabel("bottom", "map x (m)")
        self.setLabel("left", "map y (m)")
        self.setMenuEnabled(False)
        self.path = pg.PlotDataItem(
            pen=pg.mkPen("#607d8b", width=2, style=QtCore.Qt.PenStyle.DashLine)
        )
        # one item, one brush per state: replacing per-point brush lists crashes PySide6 6.12
        self.by_colour = {
            colour: pg.ScatterPlotItem(
                size=34, pxMode=True, brush=pg.mkBrush(colour), pen=pg.mkPen("k")
            )
            for colour in (PENDING, ACTIVE, DONE, LOW)
        }
        for item in self.by_colour.values():
            item.sigClicked.connect(self._clicked)
        self.reference = pg.ScatterPlotItem(
            size=46, pxMode=True, brush=None, pen=pg.mkPen("#1e88e5", width=3)
        )
        self.base = pg.ScatterPlotItem(
            size=30, pxMode=True, brush=pg.mkBrush("#d32f2f"), pen=pg.mkPen("k")
        )
        for item in (self.path, self.reference, *self.by_colour.values(), self.base):
            self.addItem(item)
        self.labels: list[pg.TextItem] = []
        self.plan: MissionPlan | None = None
        self.colours: dict[int, str] = {}
        self.base_pose: tuple[float, float, float] | None = None

    def show_plan(self, plan: MissionPlan) -> None:
        self.plan = plan
        self.colours = {s.number: PENDING for s in plan.stations}
        xs = np.array([s.x_m for s in plan.stations])
        ys = np.array([s.y_m for s in plan.stations])
        self.path.setData(xs, ys)
        ref = plan.station(plan.reference_station)
        self.reference.setData([ref.x_m], [ref.y_m])
        for label in self.labels:
            self.removeItem(label)
        self.labels = []
        for order, station in enumerate(plan.stations, start=1):
            text = pg.TextItem(f"{station.number}", color="k", anchor=(0.5, 0.5))
            text.setPos(station.x_m, station.y_m)
            text.setToolTip(f"station {station.number}, visit {order}")
            self.addItem(text)
            self.labels.append(text)
        self._draw_stations()
        self.autoRange(padding=0.25)

    def set_station_state(self, station: int, colour: str) -> None:
        if station in self.colours:
            self.colours[station] = colour
            self._draw_stations()

    def reset_progress(self) -> None:
        self.colours = dict.fromkeys(self.colours, PENDING)
        self._draw_stations()

    def show_base(self, x_m: float, y_m: float, yaw_deg: float) -> None:
        """The base's pose (map frame)."""
        self.base_pose = (x_m, y_m, yaw_deg)
        symbol = rotated(arrow_symbol(), yaw_deg)
        self.base.setData([x_m], [y_m])
        self.base.setSymbol(symbol)
        self.base.setToolTip(f"base at x {x_m:.2f} m, y {y_m:.2f} m, yaw {yaw_deg:.0f} deg")

    def _draw_stations(self) -> None:
        if self.plan is None:
            return
        for colour, item in self.by_colour.items():
            stations = [s for s in self.plan.stations if self.colours[s.number] == colour]
            item.setData(
                x=[s.x_m for s in stations],
                y=[s.y_m for s in stations],
                data=[s.number for s in stations],
            )

    def _clicked(self, _item: object, points: list[pg.SpotItem]) -> None:
        if points:
            self.station_clicked.emit(int(points[0].data()))
