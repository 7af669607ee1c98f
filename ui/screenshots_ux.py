"""Screenshots of the notification strip, its log and the growth charts for the docs:
``xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m ui.screenshots_ux docs/images``.

Quick (no mission): a window on simulated devices with an open error, news and the Notices
log; the History panel and the exported growth figure for one date and for many.
"""

from __future__ import annotations

import datetime as dt
import logging
import sys
import tempfile
from pathlib import Path

from PySide6 import QtWidgets

from ui.screenshots import SIZE, pump, save

log = logging.getLogger(__name__)

DAY = dt.date(2026, 5, 14)


def notices(out: Path) -> None:
    from devices.camera.kinect2 import load_binding
    from fieldapp.settings import Settings
    from ui.app import build_window
    from ui.state import UiState

    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings()
        settings.paths.sessions_dir = Path(tmp) / "sessions"
        window = build_window(
            settings, settings_path=Path(tmp) / "s.yaml", ui_state=UiState(Path(tmp) / "ui.ini")
        )
        window.resize(*SIZE)
        window.show()
        notifier = window.context.notifier
        notifier.info("Frame saved", "depth and colour written to frames/")
        try:
            load_binding()
        except Exception as error:  # whatever the driver raises is shown
            notifier.error("Devices not connected", error)
        notifier.warn("Table lost", "no answer on /dev/ttyUSB0", "Check its cable and power.")
        window.show_page("mission")
        pump(timeout_s=1.0)
        save(window, out, "notices")
        window.show_log()
        pump(timeout_s=1.0)
        save(window, out, "notices-log")
        window.close()


def history(out: Path) -> None:
    from fieldapp.evaluate.figures import growth_png
    from fieldapp.results.db import Observation
    from ui.results.history import HistoryPanel

    def observations(days: list[int], plants: int) -> list[Observation]:
        return [
            Observation(p, p, DAY + dt.timedelta(days=d), f"s{d}", d, 0.0, 0.0,
                        8.0 + 0.6 * p + 0.9 * d + (p % 3), 5.0)
            for d in days for p in range(1, plants + 1)
        ]  # fmt: skip

    with tempfile.TemporaryDirectory() as tmp:
        panel = HistoryPanel(Path(tmp) / "results.sqlite")
        panel.resize(1000, 520)
        panel.show()
        panel.plot_name.setText("north-field-A")
        for name, days in (("one-date", [0]), ("dates", [0, 7, 14, 28])):
            shown = observations(days, 16 if len(days) == 1 else 6)
            panel.show_observations("north-field-A", shown)
            pump(timeout_s=0.5)
            save(panel, out, f"history-{name}")
            series: dict[int, list[tuple[dt.date, float]]] = {}
            for o in shown:
                series.setdefault(o.plant_number, []).append((o.date, o.height_cm))
            path = out / f"growth-{name}.png"
            path.write_bytes(growth_png("height", series, "height over the season"))
            log.info("wrote %s", path)
        panel.close()
        panel.deleteLater()


def main() -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/images")
    out.mkdir(parents=True, exist_ok=True)
    app = QtWidgets.QApplication(sys.argv[:1])
    notices(out)
    history(out)
    app.processEvents()
    return 0


if __name__ == "__main__":
    sys.exit(main())
