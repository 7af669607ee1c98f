"""Screenshots of the Live, Mission and Calibration tools of issue 25 item 5 for the docs:
``xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m ui.screenshots_tools docs/images``.

The Live page with the automatic depth range, its histogram and a distance between two
clicked points; a paused mission and a capture opened from its grid; the calibration pages
(``ui.calibration.screenshots``: on a simulated checkerboard session, ~1 min).
"""

from __future__ import annotations

import logging
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from PySide6 import QtWidgets

from ui.screenshots import SIZE, pump, save

log = logging.getLogger(__name__)


def window_on(tmp: Path, realtime: bool) -> Any:
    from fieldapp.settings import Settings
    from ui.app import build_window
    from ui.state import UiState

    settings = Settings()
    settings.paths.sessions_dir = tmp / "sessions"
    settings.devices.realtime_simulation = realtime
    window = build_window(settings, settings_path=tmp / "s.yaml", ui_state=UiState(tmp / "ui.ini"))
    window.resize(*SIZE)
    window.show()
    hub = window.context.hub
    hub.connect_devices(settings.devices)
    pump(lambda: hub.connected, 60.0)
    return window


def live(out: Path) -> None:
    from ui.live.preview import LivePreview

    with tempfile.TemporaryDirectory() as tmp:
        window = window_on(Path(tmp), realtime=True)
        window.show_page("live")
        page = window.pages["live"]
        preview = page if isinstance(page, LivePreview) else page.findChild(LivePreview)
        pump(lambda: preview.frames_shown > 5, 30.0)
        pump(timeout_s=2.0)
        preview.freeze.setChecked(True)
        preview.pick(150, 330)
        preview.pick(380, 330)
        preview.show_reading(300, 330)
        pump(timeout_s=1.0)
        save(window, out, "live-tools")
        preview.freeze.setChecked(False)
        window.show_page("mission")  # the preview stops before the devices do
        pump(timeout_s=0.5)
        window.close()


def mission(out: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        window = window_on(Path(tmp), realtime=False)
        page = window.pages["mission"]
        window.show_page("mission")
        page.start()
        pump(lambda: page.progress.captured >= 20, 120.0)
        page.controller.pause()
        pump(timeout_s=3.0)
        save(window, out, "mission-paused")
        station = next(s for s, views in page.station_views.items() if 2 in views)
        viewer = page.open_view(station, 2)
        pump(timeout_s=1.5)
        if viewer is not None:
            save(viewer, out, "mission-capture")
            viewer.close()
        window.emergency_stop()
        pump(lambda: not page.busy, 30.0)
        window.close()


def calibration(out: Path) -> None:
    """The calibration pages in the main window (``ui.calibration.screenshots``)."""
    from ui.calibration.screenshots import shoot

    shoot(out)


AREAS = ("live", "mission", "calibration")


def main() -> int:
    """``python -m ui.screenshots_tools OUT [AREA...]``: with no area, each area in a process
    of its own (a second window's devices in one process did not connect under Xvfb)."""
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/images")
    out.mkdir(parents=True, exist_ok=True)
    chosen = sys.argv[2:]
    if not chosen:
        for area in AREAS:
            subprocess.run(
                [sys.executable, "-m", "ui.screenshots_tools", str(out), area], check=True
            )
        return 0
    app = QtWidgets.QApplication(sys.argv[:1])
    shots = {"live": live, "mission": mission, "calibration": calibration}
    for area in chosen:
        log.info("%s...", area)
        shots[area](out)
        app.processEvents()
    return 0


if __name__ == "__main__":
    sys.exit(main())
