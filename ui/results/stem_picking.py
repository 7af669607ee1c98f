"""Picking the stems of a plant to split, in the results panel: the row under the correction
bar while a split is prepared. Each click on the plant in the 3D view picks the point of its
cloud under the mouse; a click on the map picks a plan-view position; the stems can also be
typed (``x, y; x, y``, metres, map frame). The picked stems are drawn as numbered markers in
the 3D view and on the map, the plant being split highlighted; *Apply split* is enabled once
two stems are there."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from PySide6 import QtCore, QtWidgets

from fieldapp.errors import FieldappError

if TYPE_CHECKING:
    from ui.results.panel import ResultsPanel

_NUMBER = r"[-+]?\d+(?:\.\d*)?"
_POINT = re.compile(rf"\s*({_NUMBER})\s*[, ]\s*({_NUMBER})\s*")
NEAR_STEM_M = 0.02
"""A typed or map-picked stem is drawn in 3D at the lowest point of the plant this near it in
plan view (at the ground when there is none)."""


def parse_stems(text: str) -> list[tuple[float, float]]:
    """``"0.10, 0.20; 0.35, 0.22"`` -> [(0.1, 0.2), (0.35, 0.22)] (metres, map frame);
    raises :class:`FieldappError` naming the bad entry."""
    stems = []
    for part in (p for p in text.split(";") if p.strip()):
        match = _POINT.fullmatch(part)
        if match is None:
            raise FieldappError(f"stem points: {part.strip()!r} is not 'x, y' in metres")
        stems.append((float(match[1]), float(match[2])))
    return stems


def marker_points(
    stems_xy_m: list[tuple[float, float]],
    picked_m: list[NDArray[np.float64]],
    plant_m: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(S, 3) where to draw the stems: a stem picked in 3D at the point picked, another at the
    lowest point of the plant ``plant_m`` (N, 3) within :data:`NEAR_STEM_M` in plan view."""
    markers = np.zeros((len(stems_xy_m), 3))
    for i, (x, y) in enumerate(stems_xy_m):
        same = [p for p in picked_m if _text(p[0], p[1]) == _text(x, y)]
        if same:
            markers[i] = same[0]
            continue
        near = plant_m[np.hypot(plant_m[:, 0] - x, plant_m[:, 1] - y) <= NEAR_STEM_M]
        markers[i] = (x, y, float(near[:, 2].min()) if len(near) else 0.0)
    return markers


def _text(x_m: float, y_m: float) -> str:
    return f"{x_m:.3f}, {y_m:.3f}"


class StemPicker(QtWidgets.QWidget):
    """The stems of the split being prepared; ``apply_requested`` on *Apply split*."""

    apply_requested = QtCore.Signal()

    def __init__(self, panel: ResultsPanel) -> None:
        super().__init__(panel)
        self.panel = panel
        self.plant: int | None = None
        self.picked: list[NDArray[np.float64]] = []
        self.plant_m: NDArray[np.float64] = np.zeros((0, 3))
        self._build()
        panel.view3d.point_picked.connect(self._picked_3d)
        panel.view3d.pick_missed.connect(self._missed)
        panel.map.point_clicked.connect(self._picked_map)
        self.setVisible(False)

    def start(self, plant: int, plant_m: NDArray[np.float64]) -> None:
        """Prepare splitting ``plant`` (its points ``plant_m`` (N, 3)): clicks pick stems."""
        self.plant, self.plant_m, self.picked = plant, plant_m, []
        self.title.setText(f"Split plant {plant}:")
        self.stems.clear()
        self.setVisible(True)
        panel = self.panel
        if panel.tabs.currentWidget() is not panel.map:
            panel.tabs.setCurrentWidget(panel.view3d)
        panel.view3d.focus(plant_m)
        panel.view3d.start_picking(plant_m)
        panel.map.picking = True
        self._refresh()

    def end(self) -> None:
        """Leave picking: the views select plants on a click again, the markers go."""
        self.plant, self.picked = None, []
        self.setVisible(False)
        self.panel.view3d.stop_picking()
        self.panel.map.picking = False
        self.panel.map.set_markers([])

    def add(self, x_m: float, y_m: float) -> None:
        """Add a stem at (x, y) (map frame, metres)."""
        text = self.stems.text().strip()
        entry = _text(x_m, y_m)
        self.stems.setText(f"{text}; {entry}" if text else entry)

    def remove_last(self) -> None:
        entries = [p for p in self.stems.text().split(";") if p.strip()]
        self.stems.setText(";".join(entries[:-1]).strip())

    def stems_xy_m(self) -> list[tuple[float, float]]:
        return parse_stems(self.stems.text())

    def _picked_3d(self, point_m: NDArray[np.float64]) -> None:
        if self.plant is None:
            return
        self.picked.append(np.asarray(point_m, np.float64))
        self.add(float(point_m[0]), float(point_m[1]))

    def _picked_map(self, x_m: float, y_m: float) -> None:
        """A click on the map: a stem when it lands on the plant (the split would refuse a
        stem farther than :data:`~fieldapp.results.correction_ops.STEM_SNAP_M`)."""
        if self.plant is None:
            return
        from fieldapp.results.correction_ops import STEM_SNAP_M

        off_m = float(np.hypot(self.plant_m[:, 0] - x_m, self.plant_m[:, 1] - y_m).min())
        if off_m > STEM_SNAP_M:
            self.count.setText(
                f"⚠ that click is {100 * off_m:.0f} cm from plant {self.plant}: click on its stem"
            )
            return
        self.add(x_m, y_m)

    def _missed(self) -> None:
        if self.plant is not None:
            self.count.setText(f"⚠ no point of plant {self.plant} there: click on its stem")

    def _refresh(self) -> None:
        """Markers, count and *Apply split* follow the stem line."""
        try:
            stems = self.stems_xy_m()
        except FieldappError as error:
            self.count.setText(f"⚠ {error}")
            self.apply.setEnabled(False)
            return
        if self.plant is None:
            return
        self.panel.view3d.set_markers(marker_points(stems, self.picked, self.plant_m))
        self.panel.map.set_markers(stems)
        more = "" if len(stems) >= 2 else f": pick {2 - len(stems)} more"
        self.count.setText(f"{len(stems)} stem{'s' if len(stems) != 1 else ''} picked{more}")
        self.apply.setEnabled(len(stems) >= 2)
        self.remove.setEnabled(bool(stems))

    def _build(self) -> None:
        self.title = QtWidgets.QLabel("Split:")
        self.stems = QtWidgets.QLineEdit()
        self.stems.setPlaceholderText(
            "click each stem in the 3D view or on the map, or type x, y; x, y (m, map frame)"
        )
        self.stems.setToolTip(
            "The stems' feet in plan view (metres, map frame), one 'x, y' per stem, separated "
            "by ';'. Each point of the plant goes to the stem it is nearest along the plant."
        )
        self.stems.textChanged.connect(self._refresh)
        self.count = QtWidgets.QLabel("")
        self.remove = QtWidgets.QPushButton("Remove last")
        self.remove.setToolTip("Forget the last stem picked")
        self.remove.clicked.connect(self.remove_last)
        self.apply = QtWidgets.QPushButton("Apply split")
        self.apply.clicked.connect(self.apply_requested)
        self.cancel = QtWidgets.QPushButton("Cancel")
        self.cancel.clicked.connect(self.end)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        for widget in (self.title, self.stems, self.count, self.remove, self.apply, self.cancel):
            layout.addWidget(widget)
        layout.setStretchFactor(self.stems, 1)
