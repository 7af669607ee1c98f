"""Screenshots of the field GUI for the docs: ``python -m ui.screenshots docs/images``.

Runs the real window on simulated devices (instant moves) in a temporary sessions folder,
drives it like an operator (connect, start a mission, pause it mid-way, open the device
dialog and test every device, a device that fails) and grabs each screen with
``QWidget.grab()``. Run under Xvfb for the OpenGL 3D view:
``xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m ui.screenshots docs/images``.
"""

from __future__ import annotations

import logging
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from PySide6 import QtCore, QtWidgets

if TYPE_CHECKING:
    from ui.results import ResultsPanel

log = logging.getLogger(__name__)

SIZE = (1440, 900)


def pump(condition: Callable[[], bool] = lambda: False, timeout_s: float = 1.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 20)
        if condition():
            return True
        time.sleep(0.01)
    return condition()


def save(widget: QtWidgets.QWidget, out: Path, name: str) -> None:
    path = out / f"gui-{name}.png"
    widget.grab().save(str(path))
    log.info("wrote %s", path)


def shoot(out: Path) -> None:
    from fieldapp.settings import Settings
    from ui.app import build_window
    from ui.state import UiState

    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings()
        settings.paths.sessions_dir = Path(tmp) / "sessions"
        settings.devices.realtime_simulation = False
        window = build_window(
            settings, settings_path=Path(tmp) / "s.yaml", ui_state=UiState(Path(tmp) / "ui.ini")
        )
        window.resize(*SIZE)
        window.show()
        hub = window.context.hub
        live_shots(window, out, settings.devices.model_copy(update={"realtime_simulation": True}))
        hub.connect_devices(settings.devices)
        pump(lambda: hub.connected, 60.0)
        mission = window.pages["mission"]
        mission.start()  # type: ignore[attr-defined]
        pump(lambda: mission.progress.captured >= 26, 120.0)  # type: ignore[attr-defined]
        mission.controller.pause()  # type: ignore[attr-defined]
        pump(timeout_s=2.0)
        window.show_page("mission")
        pump(timeout_s=1.0)
        save(window, out, "mission")
        window.emergency_stop()
        pump(lambda: not mission.busy, 30.0)  # type: ignore[attr-defined]
        pump(timeout_s=1.0)
        save(window, out, "stopped")
        devices_dialog(window, out)
        failed_device(window, out)
        window.close()


def live_shots(window: QtWidgets.QMainWindow, out: Path, devices: object) -> None:
    """The Live page on real-time devices (a camera at 30 fps), then the other pages."""
    hub = window.context.hub  # type: ignore[attr-defined]
    hub.connect_devices(devices)
    pump(lambda: hub.connected, 60.0)
    window.show_page("live")  # type: ignore[attr-defined]
    live = window.pages["live"]  # type: ignore[attr-defined]
    pump(timeout_s=4.0)
    live.show_reading(300, 330)
    save(window, out, "live")
    live.second_view.setCurrentText("IR")
    pump(timeout_s=1.0)
    save(window, out, "live-ir")
    live.second_view.setCurrentText("Colour")
    for key in ("calibrate", "results"):
        window.show_page(key)  # type: ignore[attr-defined]
        pump(timeout_s=1.0)
        save(window, out, key)
    hub.disconnect_devices(wait=True)


def devices_dialog(window: QtWidgets.QMainWindow, out: Path) -> None:
    from ui.devices.dialog import DeviceSettingsDialog

    context = window.context  # type: ignore[attr-defined]
    dialog = DeviceSettingsDialog(context.settings.devices, context.ui_state, window)
    dialog.show()
    dialog.test_all()
    pump(lambda: not dialog.testing, 60.0)
    pump(timeout_s=0.5)
    save(dialog, out, "devices")
    dialog.base_simulated.setChecked(False)
    dialog.base_endpoint.setText("tcp://192.168.1.20:5555")
    dialog.table_port.setEditText("/dev/ttyUSB0")
    dialog.test("table")
    dialog.test("base")
    pump(lambda: not dialog.testing, 60.0)
    pump(timeout_s=0.5)
    save(dialog, out, "devices-failed")
    dialog.reject()
    dialog.deleteLater()


def failed_device(window: QtWidgets.QMainWindow, out: Path) -> None:
    context = window.context  # type: ignore[attr-defined]
    hub = context.hub
    hub.disconnect_devices(wait=True)
    devices = context.settings.devices.model_copy(update={"table_port": "/dev/ttyUSB0"})
    hub.connect_devices(devices)
    pump(lambda: bool(window.notices.cards()) and not hub.busy, 60.0)  # type: ignore[attr-defined]
    pump(timeout_s=0.5)
    save(window, out, "device-error")


def shoot_main(shoot: Callable[[Path], None]) -> int:
    """A screenshot script's ``main``: ``shoot`` into the folder named on the command line
    (default ``docs/images``)."""
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/images")
    out.mkdir(parents=True, exist_ok=True)
    app = QtWidgets.QApplication(sys.argv[:1])
    shoot(out)
    app.processEvents()
    return 0


def results_panel(folder: Path, session: Path) -> ResultsPanel:
    """A results panel on screen with ``session`` open, its database and results in
    ``folder``."""
    from fieldapp.settings import Settings
    from ui.results import ResultsPanel

    settings = Settings()
    settings.paths.results_db = folder / "results.sqlite"
    panel = ResultsPanel(settings)
    panel.resize(*SIZE)
    panel.show()
    panel.open_session(session)
    panel.results_dir.setText(str(folder / "results"))
    return panel


def main() -> int:
    return shoot_main(shoot)


if __name__ == "__main__":
    sys.exit(main())
