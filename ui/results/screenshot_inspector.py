"""The per-plant inspector's screenshot for the docs (docs/WORKSTATION.md):
``xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m ui.results.screenshot_inspector
docs/images [SESSION]``.

Simulates the default seedling plot (seed 0, every station, every view), reconstructs it in
the results panel, selects a plant and one of its leaves and grabs the panel on the Plant tab
(``workstation-results-inspector.png``) and on the Organ accuracy tab
(``workstation-results-organ-accuracy.png``).
"""

from __future__ import annotations

import logging
import sys
import tempfile
from pathlib import Path

from PySide6 import QtWidgets

from ui.screenshots import pump, results_panel

log = logging.getLogger(__name__)


def shoot(out: Path, session: Path | None = None, plant: int = 5, leaf_row: int = 2) -> None:
    """The screenshots into ``out``, of ``session`` (default: one simulated here)."""
    from fieldapp.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        if session is None:
            session = Path(tmp) / "plot"
            if main(["simulate", "--out", str(session)]) != 0:
                raise RuntimeError("simulate failed")
        panel = results_panel(Path(tmp), session)
        panel.reconstruct()
        pump(lambda: panel.results is not None, 300.0)
        panel.select_plant(plant)
        panel.tabs.setCurrentWidget(panel.inspector)
        panel.inspector.leaves.selectRow(leaf_row)
        pump(timeout_s=2.0)
        _save(panel, out / "workstation-results-inspector.png")
        panel.tabs.setCurrentWidget(panel.organ_accuracy)
        pump(timeout_s=1.0)
        _save(panel, out / "workstation-results-organ-accuracy.png")
        panel.close()


def _save(widget: QtWidgets.QWidget, path: Path) -> None:
    widget.grab().save(str(path))
    log.info("wrote %s", path)


def main() -> int:
    logging.basicConfig(level=logging.INFO)
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv)
    session = Path(sys.argv[2]) if len(sys.argv) > 2 else None
    shoot(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images"), session)
    app.processEvents()
    return 0


if __name__ == "__main__":
    sys.exit(main())
