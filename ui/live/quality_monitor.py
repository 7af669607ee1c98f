"""Capture-quality figures of the live stream, measured off the GUI thread.

Measuring a frame (:func:`devices.camera.quality.assess`) takes 20-30 ms, too long for the
GUI thread at the camera's rate; a small thread measures the newest frame a few times a
second and the result arrives as a Qt signal on the GUI thread.
"""

from __future__ import annotations

import logging
import threading

from PySide6 import QtCore

from devices.camera import CameraError
from devices.camera.frames import Intrinsics
from devices.camera.quality import QualityReport, QualityThresholds, assess
from devices.camera.stream import FrameStream

log = logging.getLogger(__name__)

PERIOD_S = 0.5


class QualityMonitor(QtCore.QObject):
    """Measures ``stream``'s newest frame every ``period_s`` while started."""

    measured = QtCore.Signal(object, object)
    """(:class:`QualityReport`, list of problem lines)."""

    def __init__(
        self,
        limits: QualityThresholds,
        period_s: float = PERIOD_S,
        parent: QtCore.QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.limits = limits
        self.period_s = period_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, stream: FrameStream, intrinsics: Intrinsics) -> None:
        self.stop()
        self._stop.clear()
        self._thread = threading.Thread(
            target=self._run, args=(stream, intrinsics), name="live-quality", daemon=True
        )
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self, stream: FrameStream, intrinsics: Intrinsics) -> None:
        while not self._stop.wait(self.period_s):
            try:
                frame = stream.latest()
            except CameraError:
                return  # the preview reports the stream's end
            if frame is None:
                continue
            report: QualityReport = assess(frame, intrinsics, self.limits)
            self.measured.emit(report, report.problems(self.limits))
