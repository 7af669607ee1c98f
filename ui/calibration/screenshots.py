"""Screenshots of the calibration pages for the docs, in the real main window:
``xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m ui.calibration.screenshots
docs/images`` (a simulated checkerboard session, about a minute).

Writes ``gui-calibrate.png`` (the overview before any calibration) and
``gui-calibrate-*.png``: the intrinsics capture step (a view picked from the list) and
solve step (error bars, reprojection overlay), the view-step session step with the remembered
folder, the stations solve step (top view), and the overview with the stations wizard left
open (its button says where it stands).
"""

from __future__ import annotations

import logging
import sys
import tempfile
from pathlib import Path

from PySide6 import QtWidgets

from ui.screenshots import SIZE, pump, save, shoot_main

log = logging.getLogger(__name__)


def shoot(out: Path) -> None:
    from fieldapp.cli import main as cli
    from fieldapp.settings import Settings
    from ui.app import build_window
    from ui.state import UiState

    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        boards = tmp / "boards"
        args = ["simulate", "--out", str(boards), "--scene", "checkerboard", "--stations", "4,5"]
        cli([*args, "--views", "0-7", "--intrinsics-images", "12"])
        settings = Settings()
        settings.paths.sessions_dir = tmp / "sessions"
        window = build_window(settings, settings_path=tmp / "s.yaml", ui_state=UiState(tmp / "u"))
        window.resize(*SIZE)
        window.show()
        window.show_page("calibrate")
        page = window.pages["calibrate"]
        pump(timeout_s=0.5)
        save(window, out, "calibrate")  # the overview, nothing calibrated yet
        intrinsics(window, page, boards, out)
        views = page.open_wizard("views")  # type: ignore[attr-defined]
        views.board_form.square_mm.setValue(50.0)
        views.next()
        views.session_page.load(boards)
        views.session_page.captures.setCurrentRow(1)
        pump(timeout_s=2.0)
        save(window, out, "calibrate-views-session")
        finish(views)
        stations = page.open_wizard("stations")  # type: ignore[attr-defined]
        stations.next()  # the session folder is remembered
        stations.next()
        stations.solve.wait(120)
        pump(timeout_s=1.0)
        save(window, out, "calibrate-stations-solve")
        page.currentWidget().back_button.click()  # type: ignore[attr-defined]
        pump(timeout_s=1.0)
        save(window, out, "calibrate-overview")
        window.close()


def intrinsics(window: QtWidgets.QWidget, page: QtWidgets.QWidget, boards: Path, out: Path) -> None:
    wizard = page.open_wizard("intrinsics")  # type: ignore[attr-defined]
    wizard.next()
    wizard.capture.add_images(sorted((boards / "intrinsics").glob("*.png")))
    wizard.capture.listing.setCurrentRow(2)
    pump(timeout_s=1.0)
    save(window, out, "calibrate-intrinsics-capture")
    wizard.next()
    wizard.solve.wait(120)
    pump(timeout_s=1.0)
    save(window, out, "calibrate-intrinsics-solve")
    finish(wizard)


def finish(wizard: QtWidgets.QWizard) -> None:
    """Solve if not yet, save, Finish: back to the overview."""
    while wizard.currentPage() is not wizard.solve:  # type: ignore[attr-defined]
        wizard.next()
    wizard.solve.wait(120)  # type: ignore[attr-defined]
    wizard.next()
    wizard.save.save()  # type: ignore[attr-defined]
    wizard.button(QtWidgets.QWizard.WizardButton.FinishButton).click()
    pump(timeout_s=0.5)


def main() -> int:
    return shoot_main(shoot)


if __name__ == "__main__":
    sys.exit(main())
