"""The correction flow's screenshots for the docs (docs/WORKSTATION.md), taken the way an
operator walks it: ``xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m
ui.results.screenshot_correction docs/images [SEED]``.

Simulates a seedling plot (seed 3 by default), reconstructs it in the results panel and then:
selects the two nearest plants (both highlighted in 3D), merges them, splits the merged plant
again by clicking its two stems in the 3D view (each click a synthesised mouse click at where
a stem of the simulation's truth is seen), deletes a plant and undoes that, and reconstructs
the session again into the same folder (the corrections come back). Writes
``workstation-correction-*.png``.
"""

from __future__ import annotations

import json
import logging
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PySide6 import QtCore, QtWidgets
from PySide6.QtTest import QTest

from ui.results.scene import depth_m, pick_on_screen
from ui.screenshots import pump, results_panel

if TYPE_CHECKING:
    from ui.results import ResultsPanel
    from ui.results.data import PlotResults

log = logging.getLogger(__name__)


def shoot(out: Path, seed: int = 3) -> None:
    from fieldapp.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        session = Path(tmp) / "plot"
        if main(["simulate", "--out", str(session), "--seed", str(seed)]) != 0:
            raise RuntimeError("simulate failed")
        panel = results_panel(Path(tmp), session)
        _reconstruct(panel)
        bar = panel.correction
        bar.author.setText("ana")
        a, b = _nearest_pair(panel)
        bar.select_plants([a, b])
        _save(panel, out, "selected")
        _apply(panel, bar.merge_action)
        _save(panel, out, "merged")
        bar.split_action.trigger()
        pump(timeout_s=1.0)
        for stem in _true_stems(session, panel, a):
            _click_stem(panel, stem)
        pump(timeout_s=1.0)
        _save(panel, out, "split-picked")
        _apply(panel, bar.picker.apply)
        _save(panel, out, "split")
        bar.select_plants([min(p.plant for p in _shown(panel).plants)])
        _apply(panel, bar.delete_action)
        _apply(panel, bar.undo_action)
        _reconstruct(panel)
        pump(lambda: not bar.workers.busy and "correction" in bar.status.text(), 120.0)
        pump(timeout_s=2.0)
        _save(panel, out, "rerun")
        panel.shutdown()
        panel.close()


def _reconstruct(panel: QtWidgets.QWidget) -> None:
    """Reconstruct the open session into the results folder (replacing what is there)."""
    QtCore.QTimer.singleShot(500, _answer_replace)
    panel.results = None  # type: ignore[attr-defined]
    panel.reconstruct()  # type: ignore[attr-defined]
    pump(lambda: panel.results is not None, 600.0)  # type: ignore[attr-defined]
    pump(timeout_s=1.0)


def _shown(panel: ResultsPanel) -> PlotResults:
    """The results ``panel`` shows; raises when it shows none (a reconstruction failed)."""
    if panel.results is None:
        raise RuntimeError("no results shown")
    return panel.results


def _answer_replace() -> None:
    """Answer *Replace* in the "Results already there" question, when it is asked."""
    for widget in QtWidgets.QApplication.topLevelWidgets():
        if isinstance(widget, QtWidgets.QMessageBox) and widget.isVisible():
            for button in widget.buttons():
                if button.text() == "Replace":
                    button.click()


def _apply(panel: QtWidgets.QWidget, action: QtCore.QObject) -> None:
    bar = panel.correction  # type: ignore[attr-defined]
    action.trigger() if hasattr(action, "trigger") else action.click()  # type: ignore[attr-defined]
    pump(lambda: not bar.workers.busy, 120.0)
    pump(timeout_s=1.0)


def _nearest_pair(panel: QtWidgets.QWidget) -> tuple[int, int]:
    plants = panel.results.plants  # type: ignore[attr-defined]
    xy = np.array([(p.x_m, p.y_m) for p in plants])
    distance = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(len(xy)) * 1e9
    i, j = np.unravel_index(np.argmin(distance), distance.shape)
    return tuple(sorted((plants[i].plant, plants[j].plant)))


def _true_stems(session: Path, panel: QtWidgets.QWidget, plant: int) -> list[np.ndarray]:
    """The simulation's true stems under ``plant``'s points (map frame), nearest first."""
    truth = json.loads((session / "truth.json").read_text())
    stems = np.array([[p["map_x_m"], p["map_y_m"]] for p in truth["plants"]])
    points = panel.results.plant_clouds[plant].points  # type: ignore[attr-defined]
    near = [s for s in stems if np.hypot(*(points[:, :2] - s).T).min() < 0.02]
    return near


def _click_stem(panel: QtWidgets.QWidget, stem_xy_m: np.ndarray) -> None:
    """A mouse click in the 3D view where a click picks a point of the plant within 3 cm of
    the stem in plan view (a seedling's leaves may hide its foot from above)."""
    view = panel.view3d.view  # type: ignore[attr-defined]
    widget, points = view.widget, view.pickable
    pixels, depth = widget.to_screen(points), depth_m(points, widget.mvp())
    plan_m = np.hypot(*(points[:, :2] - stem_xy_m).T)
    near = np.flatnonzero(plan_m < 0.03)
    for i in near[np.argsort(plan_m[near])]:
        position = QtCore.QPoint(round(pixels[i, 0]), round(pixels[i, 1]))
        hit = pick_on_screen((position.x(), position.y()), pixels, depth)
        if hit is not None and plan_m[hit] < 0.03:
            QTest.mouseClick(widget, QtCore.Qt.MouseButton.LeftButton, pos=position)
            return
    log.warning("no point of the stem at %s can be clicked", stem_xy_m)


def _save(widget: QtWidgets.QWidget, out: Path, name: str) -> None:
    path = out / f"workstation-correction-{name}.png"
    widget.grab().save(str(path))
    log.info("wrote %s", path)


def main() -> int:
    logging.basicConfig(level=logging.INFO)
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv)
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    shoot(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images"), seed)
    app.processEvents()
    return 0


if __name__ == "__main__":
    sys.exit(main())
