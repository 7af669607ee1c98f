"""The mission's progress: a bar with captures done, elapsed and remaining time and the
current step; a station x view grid filled with each capture's thumbnail and quality; the log
of warnings and retries."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from PySide6 import QtCore, QtGui, QtWidgets

from fieldapp.mission.events import MissionProgress, MissionWarning, StationReached, ViewCaptured
from fieldapp.mission.plan import MissionPlan

THUMB_W, THUMB_H = 64, 53
ELAPSED_TICK_MS = 1000
OK_COLOUR = QtGui.QColor("#c8e6c9")
LOW_COLOUR = QtGui.QColor("#ffe0b2")


def format_duration(seconds: float | None) -> str:
    """``1 h 02 min``, ``3 min 05 s``, ``42 s``; ``-`` when unknown."""
    if seconds is None:
        return "-"
    total = round(seconds)
    hours, rest = divmod(total, 3600)
    minutes, secs = divmod(rest, 60)
    if hours:
        return f"{hours} h {minutes:02d} min"
    if minutes:
        return f"{minutes} min {secs:02d} s"
    return f"{secs} s"


def thumbnail_icon(rgb: NDArray[np.uint8]) -> QtGui.QIcon:
    """An icon of an (h, w, 3) uint8 RGB thumbnail."""
    image = np.ascontiguousarray(rgb)
    height, width = image.shape[:2]
    qimage = QtGui.QImage(image.data, width, height, 3 * width, QtGui.QImage.Format.Format_RGB888)
    return QtGui.QIcon(QtGui.QPixmap.fromImage(qimage.copy()))


class ProgressPanel(QtWidgets.QWidget):
    """Fed by the mission controller's signals (GUI thread); :attr:`view_opened` (station,
    view) when a captured thumbnail is double-clicked."""

    view_opened = QtCore.Signal(int, int)

    def __init__(
        self,
        parent: QtWidgets.QWidget | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(parent)
        self.clock = clock
        self._last: tuple[MissionProgress, float] | None = None  # latest progress, when
        self.paused = False
        self.ticker = QtCore.QTimer(self)
        self.ticker.setInterval(ELAPSED_TICK_MS)
        self.ticker.timeout.connect(self.tick)
        self.bar = QtWidgets.QProgressBar()
        self.bar.setFormat("%v of %m captures")
        self.times = QtWidgets.QLabel("No mission yet.")
        self.step = QtWidgets.QLabel("")
        self.grid = QtWidgets.QTableWidget(0, 0)
        self.grid.setIconSize(QtCore.QSize(THUMB_W, THUMB_H))
        self.grid.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.grid.horizontalHeader().setDefaultSectionSize(THUMB_W + 10)
        self.grid.verticalHeader().setDefaultSectionSize(THUMB_H + 8)
        self.grid.cellDoubleClicked.connect(self._double_clicked)
        self.stations: dict[int, int] = {}  # row -> station
        self.log = QtWidgets.QListWidget()
        self.log.setMaximumHeight(110)
        self.rows: dict[int, int] = {}
        self.captured = 0
        self._started_s = time.monotonic()
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.bar)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.times, 1)
        row.addWidget(self.step, 1)
        layout.addLayout(row)
        layout.addWidget(self.grid, 1)
        layout.addWidget(QtWidgets.QLabel("Warnings and retries:"))
        layout.addWidget(self.log)

    def show_plan(self, plan: MissionPlan, done: list[tuple[int, int]] | None = None) -> None:
        """An empty grid for ``plan`` (``done``: captures a resumed session already has)."""
        stations = plan.station_numbers()
        self.rows = {station: row for row, station in enumerate(stations)}
        self.stations = {row: station for station, row in self.rows.items()}
        self.grid.clear()
        self.grid.setRowCount(len(stations))
        self.grid.setColumnCount(plan.views.count)
        self.grid.setVerticalHeaderLabels([f"station {s}" for s in stations])
        self.grid.setHorizontalHeaderLabels([f"view {v}" for v in range(plan.views.count)])
        for station, view in done or []:
            self._cell(station, view, "captured earlier", OK_COLOUR)
        self.captured = 0
        total = len(plan.capture_keys())
        self.bar.setRange(0, total)
        self.bar.setValue(len(done or []))
        self.times.setText(f"{total} captures planned")
        self.step.clear()
        self._started_s = time.monotonic()

    def add_view(self, event: ViewCaptured) -> None:
        self.captured += 1
        q = event.quality
        tip = (
            f"station {event.station}, view {event.view} at {event.angle_deg:.2f} deg\n"
            f"fill {q.fill_rate:.1%}, flying {q.flying_ratio:.2%}, over {q.overexposed:.1%}, "
            f"under {q.underexposed:.1%}; attempts {event.attempts}"
        )
        item = self._cell(
            event.station, event.view, tip, OK_COLOUR if event.quality_ok else LOW_COLOUR
        )
        if item is not None:
            item.setIcon(thumbnail_icon(event.thumbnail))
            item.setText(f"{q.fill_rate:.0%}")
            self.follow(event.station, event.view)

    def _cell(
        self, station: int, view: int, tip: str, colour: QtGui.QColor
    ) -> QtWidgets.QTableWidgetItem | None:
        row = self.rows.get(station)
        if row is None or view >= self.grid.columnCount():
            return None
        item = QtWidgets.QTableWidgetItem()
        item.setToolTip(tip)
        item.setBackground(colour)
        self.grid.setItem(row, view, item)
        return item

    def _double_clicked(self, row: int, column: int) -> None:
        item = self.grid.item(row, column)
        if item is not None and row in self.stations:  # an empty cell has nothing to show
            self.view_opened.emit(self.stations[row], column)

    def set_progress(self, progress: MissionProgress) -> None:
        self.bar.setRange(0, progress.total)
        self.bar.setValue(progress.done)
        self._last = (progress, self.clock())
        self._show_times(progress.elapsed_s)
        self.step.setText(progress.step)
        if not self.ticker.isActive():
            self.ticker.start()

    @QtCore.Slot()
    def tick(self) -> None:
        """The elapsed time keeps counting between progress reports, pauses included."""
        if self._last is not None:
            progress, at_s = self._last
            self._show_times(progress.elapsed_s + self.clock() - at_s)

    def set_paused(self, paused: bool) -> None:
        """The mission holds (or carries on): the times say so at once."""
        self.paused = paused
        self.tick()

    def _show_times(self, elapsed_s: float) -> None:
        remaining_s = self._last[0].remaining_s if self._last is not None else None
        state = " (paused)" if self.paused else ""
        self.times.setText(
            f"elapsed {format_duration(elapsed_s)}{state} · "
            f"remaining {format_duration(remaining_s)}"
        )

    def finish(self, text: str) -> None:
        """The mission ended: ``text`` replaces the time remaining."""
        self._last = None
        self.ticker.stop()
        self.times.setText(text)
        self.step.clear()

    def add_station(self, event: StationReached) -> None:
        self.step.setText(
            f"at station {event.station} (x {event.x_m:.2f} m, y {event.y_m:.2f} m, "
            f"yaw {event.yaw_deg:.0f} deg)"
        )
        self.follow(event.station)

    def follow(self, station: int, view: int = 0) -> None:
        """Scroll the grid to the station being captured and mark its row."""
        row = self.rows.get(station)
        if row is None:
            return
        self.grid.setCurrentCell(row, min(view, max(0, self.grid.columnCount() - 1)))
        self.grid.scrollTo(self.grid.model().index(row, view))

    def add_warning(self, event: MissionWarning) -> None:
        stamp = time.strftime("%H:%M:%S")
        self.log.insertItem(0, f"{stamp} {event.text}")

    def add_line(self, text: str) -> None:
        self.log.insertItem(0, f"{time.strftime('%H:%M:%S')} {text}")
