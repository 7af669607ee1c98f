"""The Live page: what the camera sees now.

A QTimer polls :meth:`FrameStream.latest` (which never blocks) and shows a new frame when one
has arrived: depth colour-mapped with a colour bar, beside (or above) the registered colour
or IR image (:mod:`ui.live.image_panel`); the colour range automatic or set by hand, over a
histogram of the depths (:mod:`ui.live.depth_range`); the depth and 3D point under the
cursor; the distance in metres between two clicked points; the camera's and the display's
frame rates and the frames dropped; the capture-quality figures (measured on a thread,
:mod:`ui.live.quality_monitor`); the current frame's points in 3D. Freeze holds the frame;
Save writes it (depth PNG in mm, colour, IR, JSON) on a worker.

Nothing is decoded, measured or painted while the operator cannot see the page: the poll
timer and the quality thread stop when the preview is hidden (another page shown) or its window
minimised, and start again when it is seen (:attr:`LivePreview.displaying`). The stream itself
keeps running: a mission reads its frames.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING

from PySide6 import QtCore, QtGui, QtWidgets

from devices.camera import CameraError
from devices.camera.frames import Frame, Intrinsics
from devices.camera.quality import QualityReport, QualityThresholds
from ui.live.cloud_view import CloudView
from ui.live.depth_range import DepthRange
from ui.live.frame_math import (
    PixelReading,
    distance_m,
    ir_for_display,
    pick_point,
    read_pixel,
    save_frame,
    valid_depths_m,
)
from ui.live.help import MEASURE_HELP, QUALITY_HELP, STREAM_HELP
from ui.live.image_panel import ImagePanel
from ui.live.quality_monitor import QualityMonitor
from ui.workers import WorkerSet

if TYPE_CHECKING:
    from devices.camera.stream import FrameStream
    from fieldapp.rig import Rig
    from ui.context import AppContext

log = logging.getLogger(__name__)

POLL_MS = 40
CLOUD_PERIOD_S = 0.5
HISTOGRAM_PERIOD_S = 0.25
SECOND_VIEWS = ("Colour", "IR", "None")


class DisplayRate:
    """Frames shown per second over the last ``window_s``."""

    def __init__(self, window_s: float = 2.0) -> None:
        self.window_s = window_s
        self._times: list[float] = []

    def tick(self, now_s: float) -> None:
        self._times.append(now_s)
        self._times = [t for t in self._times if now_s - t <= self.window_s]

    @property
    def fps(self) -> float:
        span = self._times[-1] - self._times[0] if len(self._times) > 1 else 0.0
        return (len(self._times) - 1) / span if span > 0 else 0.0


def quality_rows(report: QualityReport, limits: QualityThresholds) -> list[tuple[str, str, bool]]:
    """(figure, value, within its limit) for each figure of ``report``."""
    r, q = report, limits
    return [
        ("depth fill rate", f"{r.fill_rate:.1%}", r.fill_rate >= q.min_fill_rate),
        ("crop region", f"{r.crop_fraction:.1%}", r.crop_fraction >= q.min_crop_fraction),
        ("flying pixels", f"{r.flying_ratio:.2%}", r.flying_ratio <= q.max_flying_ratio),
        ("over-exposed", f"{r.overexposed:.1%}", r.overexposed <= q.max_overexposed),
        ("under-exposed", f"{r.underexposed:.1%}", r.underexposed <= q.max_underexposed),
        ("frame age", f"{1000 * r.age_s:.0f} ms", r.age_s <= q.max_age_s),
    ]


class LivePreview(QtWidgets.QWidget):
    """Follows the hub's stream; works as well on a stream given to :meth:`attach`."""

    def __init__(self, context: AppContext, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.context = context
        self.stream: FrameStream | None = None
        self.intrinsics: Intrinsics | None = None
        self.frame: Frame | None = None
        self.frames_shown = 0
        self._shown_frame_id = 0
        self._cloud_due_s = 0.0
        self._histogram_due_s = 0.0
        self.picks: list[PixelReading] = []
        self._stream_failed = False
        self.rate = DisplayRate()
        self._workers = WorkerSet()
        self.limits = context.settings.camera_quality.thresholds()
        self.monitor = QualityMonitor(self.limits, parent=self)
        self.monitor.measured.connect(self.show_quality)
        self._build()
        self.timer = QtCore.QTimer(self)
        self.timer.setInterval(POLL_MS)
        self.timer.timeout.connect(self.poll)
        self._watched_window: QtWidgets.QWidget | None = None
        context.hub.rig_changed.connect(self._rig_changed)

    # --- layout -----------------------------------------------------------------------------

    def _build(self) -> None:
        self.second_view = QtWidgets.QComboBox()
        self.second_view.addItems(SECOND_VIEWS)
        self.second_view.currentTextChanged.connect(self._second_view_changed)
        self.depth_range = DepthRange(self)
        self.low_m, self.high_m = self.depth_range.low_m, self.depth_range.high_m
        self.freeze = QtWidgets.QPushButton("Freeze")
        self.freeze.setCheckable(True)
        self.freeze.toggled.connect(lambda on: self.freeze.setText("Frozen" if on else "Freeze"))
        self.save_button = QtWidgets.QPushButton("Save frame...")
        self.save_button.clicked.connect(self.choose_and_save)
        tools = QtWidgets.QHBoxLayout()
        for widget in (
            QtWidgets.QLabel("Beside depth:"), self.second_view,
            QtWidgets.QLabel("Depth range (m):"), self.depth_range.auto, self.low_m,
            QtWidgets.QLabel("to"), self.high_m,
        ):  # fmt: skip
            tools.addWidget(widget)
        tools.addStretch(1)
        tools.addWidget(self.freeze)
        tools.addWidget(self.save_button)
        self.images = ImagePanel()
        self.images.scene().sigMouseMoved.connect(self._mouse_moved)
        self.images.scene().sigMouseClicked.connect(self._mouse_clicked)
        self.depth_range.levels_changed.connect(self.images.set_levels)
        self.readout = QtWidgets.QLabel("Point at the depth image to read depth and 3D position.")
        self.cloud = CloudView()
        images_and_cursor = QtWidgets.QWidget()
        column = QtWidgets.QVBoxLayout(images_and_cursor)
        column.setContentsMargins(0, 0, 0, 0)
        column.addWidget(self.images, 1)
        column.addWidget(self.readout)
        left = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        left.addWidget(images_and_cursor)
        left.addWidget(self.cloud)
        left.setSizes([520, 300])
        split = QtWidgets.QSplitter()
        split.addWidget(left)
        split.addWidget(self._side_panel())
        split.setSizes([900, 280])
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(tools)
        layout.addWidget(split, 1)

    def _side_panel(self) -> QtWidgets.QWidget:
        self.stream_label = QtWidgets.QLabel("No camera: press Connect.")
        self.stream_label.setWordWrap(True)
        self.stream_label.setToolTip(STREAM_HELP)
        self.quality_table = QtWidgets.QWidget()
        grid = QtWidgets.QGridLayout(self.quality_table)
        grid.setContentsMargins(0, 0, 0, 0)
        self.quality_values: list[tuple[QtWidgets.QLabel, QtWidgets.QLabel]] = []
        for row in range(6):
            name, value = QtWidgets.QLabel("-"), QtWidgets.QLabel("-")
            grid.addWidget(name, row, 0)
            grid.addWidget(value, row, 1)
            self.quality_values.append((name, value))
        self.quality_verdict = QtWidgets.QLabel("Quality: waiting for frames")
        self.quality_verdict.setWordWrap(True)
        quality = QtWidgets.QWidget()
        rows = QtWidgets.QVBoxLayout(quality)
        rows.setContentsMargins(0, 0, 0, 0)
        rows.addWidget(self.quality_table)
        rows.addWidget(self.quality_verdict)
        self.distance_label = QtWidgets.QLabel(MEASURE_PROMPT)
        self.distance_label.setWordWrap(True)
        self.distance_label.setToolTip(MEASURE_HELP)
        self.distance_label.setTextInteractionFlags(
            QtCore.Qt.TextInteractionFlag.TextSelectableByMouse
        )
        panel = QtWidgets.QWidget()
        column = QtWidgets.QVBoxLayout(panel)
        for title, widget in (
            ("Stream", self.stream_label), ("Capture quality", quality),
            ("Depth histogram", self.depth_range.histogram), ("Distance", self.distance_label),
        ):  # fmt: skip
            column.addWidget(QtWidgets.QLabel(f"<b>{title}</b>"))
            column.addWidget(widget)
        column.addStretch(1)
        return panel

    # --- the stream -------------------------------------------------------------------------

    def attach(self, stream: FrameStream | None, intrinsics: Intrinsics | None) -> None:
        """Show ``stream`` (``None``: nothing) and measure its quality (while seen)."""
        self.monitor.stop()
        self.timer.stop()
        self.stream, self.intrinsics = stream, intrinsics
        self._stream_failed = False
        if stream is None or intrinsics is None:
            self.stream_label.setText("No camera: press Connect.")
            return
        self.stream_label.setText("Waiting for the first frame...")
        self._update_activity()

    # --- only while seen ----------------------------------------------------------------------

    @property
    def seen(self) -> bool:
        """The operator can see the preview: shown, on the current page, window not minimised."""
        return self.isVisible() and not self.window().isMinimized()

    @property
    def displaying(self) -> bool:
        """Frames are being decoded and painted, quality measured."""
        return self.timer.isActive()

    def _update_activity(self) -> None:
        """Poll and measure exactly while a working stream is seen."""
        stream, intrinsics = self.stream, self.intrinsics
        working = stream is not None and intrinsics is not None and not self._stream_failed
        want = working and self.seen
        if want and stream is not None and intrinsics is not None and not self.timer.isActive():
            self.monitor.start(stream, intrinsics)
            self.timer.start()
        elif not want and self.timer.isActive():
            self.timer.stop()
            self.monitor.stop()

    def showEvent(self, event: QtGui.QShowEvent) -> None:
        super().showEvent(event)
        self._watch_window()
        self._update_activity()

    def hideEvent(self, event: QtGui.QHideEvent) -> None:
        super().hideEvent(event)
        self._update_activity()

    def _watch_window(self) -> None:
        """Follow the window's minimised state (a minimised window hides no child)."""
        window = self.window()
        if window is not self._watched_window:
            if self._watched_window is not None:
                self._watched_window.removeEventFilter(self)
            window.installEventFilter(self)
            self._watched_window = window

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:
        if event.type() == QtCore.QEvent.Type.WindowStateChange:
            self._update_activity()
        return False

    def _rig_changed(self, rig: Rig | None) -> None:
        stream = self.context.hub.stream
        self.attach(stream, rig.camera.intrinsics if rig is not None else None)

    @QtCore.Slot()
    def poll(self) -> None:
        """Show the newest frame if it is new (never waits for one)."""
        if self.stream is None:
            return
        try:
            frame = self.stream.latest()
        except CameraError as error:
            last = self.stream.last_frame()  # the end stays on screen, however fast it came
            if last is not None and id(last) != self._shown_frame_id:
                self._shown_frame_id = id(last)
                self.show_frame(last)
            self._stream_ended(error)
            return
        if frame is not None and id(frame) != self._shown_frame_id and not self.freeze.isChecked():
            self._shown_frame_id = id(frame)
            self.show_frame(frame)
        self._show_rates()

    def show_frame(self, frame: Frame) -> None:
        self.frame = frame
        self.frames_shown += 1
        now_s = time.monotonic()
        self.rate.tick(now_s)
        first = self.images.depth_item.image is None
        depths_m = valid_depths_m(frame.depth_m)
        self.depth_range.follow(depths_m)
        self.images.show_depth(frame.depth_m)
        if first:
            self.images.fit()
        self._show_second()
        if now_s >= self._histogram_due_s:
            self._histogram_due_s = now_s + HISTOGRAM_PERIOD_S
            self.depth_range.show_histogram(depths_m)
        if self.intrinsics is not None and now_s >= self._cloud_due_s:
            self._cloud_due_s = now_s + CLOUD_PERIOD_S
            self.cloud.show_frame(frame, self.intrinsics)

    def _show_second(self) -> None:
        frame, kind = self.frame, self.second_view.currentText()
        if frame is None or kind == "None":
            return
        if kind == "IR" and frame.ir is not None:
            self.images.second_item.setImage(ir_for_display(frame.ir), levels=(0, 255))
        else:
            self.images.second_item.setImage(frame.color, levels=(0, 255))

    def _show_rates(self) -> None:
        if self.stream is None or self._stream_failed:
            return
        stats = self.stream.stats()
        self.stream_label.setText(
            f"camera {stats.fps:.1f} fps · shown {self.rate.fps:.1f} fps<br>"
            f"dropped by the camera: {stats.camera_dropped}<br>"
            f"replaced before shown: {stats.overwritten}<br>frames: {stats.frames}"
        )

    def _stream_ended(self, error: CameraError) -> None:
        self.timer.stop()
        self.monitor.stop()
        if not self._stream_failed:
            self._stream_failed = True
            self.stream_label.setText(f"<span style='color:#c62828'>Stream ended: {error}</span>")
            self.context.notifier.error("Live camera", error)

    # --- readouts ---------------------------------------------------------------------------

    @QtCore.Slot(object, object)
    def show_quality(self, report: QualityReport, problems: list[str]) -> None:
        rows = quality_rows(report, self.limits)
        for (name_label, value_label), (name, value, ok) in zip(
            self.quality_values, rows, strict=True
        ):
            name_label.setText(name)
            name_label.setToolTip(QUALITY_HELP.get(name, ""))
            value_label.setToolTip(QUALITY_HELP.get(name, ""))
            colour, mark = ("#2e8b3a", "✔") if ok else ("#c62828", "✘")
            value_label.setText(f"<span style='color:{colour}'>{mark} {value}</span>")
        if problems:
            self.quality_verdict.setText(
                "<span style='color:#c62828'>Not ready:</span> " + "; ".join(problems)
            )
        else:
            self.quality_verdict.setText("<span style='color:#2e8b3a'>Ready to capture</span>")

    def _mouse_moved(self, position: QtCore.QPointF) -> None:
        plot = self.images.depth_plot
        if self.frame is None or self.intrinsics is None:
            return
        if not plot.sceneBoundingRect().contains(position):
            return
        point = plot.vb.mapSceneToView(position)
        self.show_reading(int(point.x()), int(point.y()))

    def show_reading(self, u: int, v: int) -> None:
        """Show the depth and 3D point at pixel (``u``, ``v``) of the shown frame."""
        if self.frame is None or self.intrinsics is None:
            return
        reading = read_pixel(self.frame.depth_m, self.intrinsics, u, v)
        if reading is None:
            return
        if reading.point_m is None:
            self.readout.setText(f"pixel ({u}, {v}): no depth")
            return
        x, y, z = reading.point_m
        self.readout.setText(
            f"pixel ({u}, {v}): depth {reading.depth_m:.3f} m · camera x {x:+.3f} m, "
            f"y {y:+.3f} m, z {z:+.3f} m"
        )

    def _second_view_changed(self, kind: str) -> None:
        self.images.show_second(kind)
        self._show_second()

    # --- distance between two picked points --------------------------------------------------

    def _mouse_clicked(self, event: object) -> None:
        button = event.button()  # type: ignore[attr-defined]
        if button == QtCore.Qt.MouseButton.RightButton:
            self.clear_picks()
            return
        if self.frame is None or button != QtCore.Qt.MouseButton.LeftButton:
            return
        position = event.scenePos()  # type: ignore[attr-defined]
        for plot in (self.images.depth_plot, self.images.second_plot):
            if plot.isVisible() and plot.sceneBoundingRect().contains(position):
                point = plot.vb.mapSceneToView(position)
                self.pick(int(point.x()), int(point.y()))
                return

    def pick(self, u: int, v: int) -> None:
        """Pick the measured point at (or nearest) pixel (``u``, ``v``) of the shown frame: the
        first and second picks give a distance, a third starts a new pair."""
        if self.frame is None or self.intrinsics is None:
            return
        reading = pick_point(self.frame.depth_m, self.intrinsics, u, v)
        if reading is None:
            self.distance_label.setText(f"pixel ({u}, {v}): no depth near it; pick another.")
            return
        if len(self.picks) == 2:
            self.picks = []
        self.picks.append(reading)
        self.images.show_marks([(p.u, p.v) for p in self.picks])
        self.distance_label.setText(measurement_text(self.picks))

    def clear_picks(self) -> None:
        self.picks = []
        self.images.show_marks([])
        self.distance_label.setText(MEASURE_PROMPT)

    # --- saving and closing -----------------------------------------------------------------

    def choose_and_save(self) -> None:
        if self.frame is None or self.intrinsics is None:
            self.context.notifier.warn("Save frame", "No frame to save yet.", "Connect first.")
            return
        start = self.context.ui_state.last_folder("frames")
        name = QtWidgets.QFileDialog.getExistingDirectory(self, "Save the frame into", str(start))
        if name:
            self.context.ui_state.set_last_folder("frames", Path(name))
            self.save_to(Path(name))

    def save_to(self, folder: Path) -> None:
        """Write the shown frame into ``folder`` on a worker; a notice says where."""
        frame, intrinsics = self.frame, self.intrinsics
        if frame is None or intrinsics is None:
            return
        self._workers.run(
            lambda: save_frame(folder, frame, intrinsics),
            lambda paths: self.context.notifier.info(
                "Frame saved", f"{len(paths)} files in {folder}"
            ),
            lambda error: self.context.notifier.error("Frame not saved", error),
        )

    @property
    def saving(self) -> bool:
        return self._workers.busy

    def shutdown(self) -> None:
        self.timer.stop()
        self.monitor.stop()
        self._workers.wait()


MEASURE_PROMPT = "Click two points on the depth or colour image to measure between them."


def measurement_text(picks: list[PixelReading]) -> str:
    """The picked points (camera frame) and, with two, the 3D distance between them."""
    lines = []
    for name, pick in zip("AB", picks, strict=False):
        x, y, z = pick.point_m or (0.0, 0.0, 0.0)
        lines.append(f"{name}: pixel ({pick.u}, {pick.v}), x {x:+.3f} y {y:+.3f} z {z:+.3f} m")
    if len(picks) == 2 and picks[0].point_m is not None and picks[1].point_m is not None:
        length_m = distance_m(picks[0].point_m, picks[1].point_m)
        lines.append(f"<b>distance A-B: {length_m:.3f} m</b> (in 3D)")
    else:
        lines.append("Click the second point.")
    return "<br>".join(lines)
