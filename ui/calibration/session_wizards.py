"""The view-to-view, station-to-station and ground wizards: each solves from a session and
saves its part of the rig's calibration (``view_step``, ``stations``, ``ground``)."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from PySide6 import QtWidgets

from devices.camera.stream import FrameStream
from fieldapp.calib import service
from fieldapp.calib.board import Board
from fieldapp.calib.ground import GroundResult
from fieldapp.calib.stations import StationsResult
from fieldapp.calib.verdict import (
    Verdict,
    ground_verdict,
    stations_verdict,
    views_verdict,
)
from fieldapp.calib.views import ViewStepResult, calibrate_view_step
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration
from fieldapp.io.session import Session
from ui.calibration.board_form import BoardForm
from ui.calibration.pages import CalibrationWizard, PreparePage, SavePage, SolvePage
from ui.calibration.pictures import StationLayout
from ui.calibration.session_page import SessionPage
from ui.state import UiState

VIEWS_TEXT = """<p>Solves the turntable's view step (view k+1 into view k, the paper's Eq. 9)
from a checkerboard seen whole at two consecutive views.</p><ul>
<li>Stand a rigid board (default 9 x 6 inner corners, 50 mm squares) about 1.1 m from the
camera, between the directions of views 0 and 1, facing the camera.</li>
<li>Capture views 0 and 1 (or the whole turn) without touching the board; a session of the
reference station is enough. Several boards or heights give a cross-check.</li></ul>"""
STATIONS_TEXT = """<p>Solves where each station stands relative to the reference station, from
boards seen by two neighbouring stations.</p><ul>
<li>Lay one board (default 9 x 6 inner corners, 40 mm squares) flat on the soil midway between
each pair of neighbouring stations, a little to the side, where both see it whole.</li>
<li>Capture every station's full turn without moving the boards. Needs the view step first.</li>
</ul>"""
GROUND_TEXT = """<p>Finds the ground plane seen from the reference station (all its views
joined) and sets the field frame: z up, 0 on the ground, origin below the camera.</p><ul>
<li>Clear the soil around the reference station of boards, tools and people.</li>
<li>Capture the reference station's full turn. Needs the view step and the stations first.</li>
</ul>"""


def station_lines(result: StationsResult, reference: int) -> list[str]:
    """Where each station's camera (view 0) stands, named with its frame and axes."""
    lines = [
        f"Station cameras in the reference frame (station {reference}'s camera at view 0: "
        "x right, y down, z forward):"
    ]
    for station, parent in sorted(result.tree.items()):
        x, y, z = result.T_reference_station[station][:3, 3]
        lines.append(
            f"  station {station} (joined through station {parent}): "
            f"x {x:+.3f} m, y {y:+.3f} m, z {z:+.3f} m"
        )
    return lines


class _SessionWizard(CalibrationWizard):
    def __init__(
        self,
        title: str,
        calibration_path: Path,
        board: Board | None,
        stream: FrameStream | None,
        serial: str | None,
        parent: QtWidgets.QWidget | None,
        ui_state: UiState | None,
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle(title)
        self.calibration_path, self.serial = calibration_path, serial
        self.board_form = BoardForm(board or Board(9, 6, 40.0))
        self.session_page = SessionPage(self.board_form.board, stream, self.in_force, ui_state)

    def _add_pages(self, prepare: PreparePage, solve: SolvePage, save: SavePage) -> None:
        """Every session wizard's pages: prepare, choose or capture the session, solve, save."""
        self.solve, self.save = solve, save
        for page in (prepare, self.session_page, solve, save):
            self.addPage(page)
        self.watch_solve()

    def in_force(self) -> Calibration | None:
        """The rig's calibration file as it is now (None when absent)."""
        path = (
            Path(self.save.path.text().strip()) if hasattr(self, "save") else self.calibration_path
        )
        return service.in_force(path)

    @property
    def session(self) -> Session:
        if self.session_page.session is None:
            raise FieldappError("choose a session first")
        return self.session_page.session

    def base(self, current: Calibration | None) -> Calibration:
        return current if current is not None else self.session.calibration

    def previews(self) -> list[Any]:
        return [self.session_page.preview]

    def catch_up(self) -> None:
        """On the session step, load the session chosen meanwhile in another wizard."""
        if self.currentPage() is self.session_page:
            self.session_page.load_remembered()


class ViewsWizard(_SessionWizard):
    def __init__(
        self,
        calibration_path: Path,
        stream: FrameStream | None = None,
        serial: str | None = None,
        parent: QtWidgets.QWidget | None = None,
        ui_state: UiState | None = None,
    ) -> None:
        super().__init__(
            "Calibrate view to view",
            calibration_path,
            Board(9, 6, 50.0),
            stream,
            serial,
            parent,
            ui_state,
        )
        self._add_pages(
            PreparePage("What to prepare", VIEWS_TEXT, self.board_form),
            SolvePage(
                lambda: partial(calibrate_view_step, self.session, self.board_form.board()),
                self._describe,
            ),
            SavePage(calibration_path, self._update),
        )

    def _nominal_deg(self) -> float:
        return service.nominal_step_deg(self.session)

    def _describe(self, result: ViewStepResult) -> tuple[list[str], Verdict]:
        t = result.T_view_k_view_k1[:3, 3]
        lines = [
            f"turn {result.angle_deg:.4f} degrees, translation "
            + " ".join(f"{x:+.4f}" for x in t)
            + " m",
            f"feature point RMSE {1000 * result.rmse_m:.2f} mm over {result.points} corners",
            *([result.depth_offset.text()] if result.depth_offset else []),
            *[f"  {pair}" for pair in result.pairs],
            *[f"warning: {w}" for w in result.warnings],
        ]
        return lines, views_verdict(result, self._nominal_deg())

    def _update(self, current: Calibration | None) -> Calibration:
        result: ViewStepResult = self.solve.result
        return service.merge_view_step(self.base(current), result, self._nominal_deg(), self.serial)


class StationsWizard(_SessionWizard):
    def __init__(
        self,
        calibration_path: Path,
        stream: FrameStream | None = None,
        serial: str | None = None,
        reference: int = 5,
        parent: QtWidgets.QWidget | None = None,
        ui_state: UiState | None = None,
    ) -> None:
        super().__init__(
            "Calibrate station to station",
            calibration_path,
            Board(9, 6, 40.0),
            stream,
            serial,
            parent,
            ui_state,
        )
        self.reference = reference
        self.layout_view = StationLayout()
        self._add_pages(
            PreparePage("What to prepare", STATIONS_TEXT, self.board_form),
            SolvePage(
                self._solve,
                self._describe,
                self.layout_view,
                self._show_layout,
            ),
            SavePage(calibration_path, self._update),
        )

    def _show_layout(self, result: StationsResult) -> None:
        """The top view, levelled by the ground of the calibration in force when it has one."""
        ground = self.base(self.in_force()).ground
        self.layout_view.show_result(
            result, self.reference, None if ground is None else ground.matrix
        )

    def _solve(self) -> Callable[[], StationsResult]:
        return service.stations_job(
            self.base(self.in_force()), self.session, self.board_form.board(), self.reference
        )

    def _describe(self, result: StationsResult) -> tuple[list[str], Verdict]:
        lines = [
            *[
                f"stations {p.station_a}-{p.station_b} via {', '.join(p.boards)}: RMSE "
                f"{1000 * p.fit.rmse_m:.2f} mm"
                for p in result.pairs
            ],
            *station_lines(result, self.reference),
            f"joint refinement: RMSE {1000 * result.bundle.rmse_m:.2f} mm over "
            f"{result.bundle.sightings} sightings",
            *[f"warning: {w}" for w in result.warnings],
        ]
        return lines, stations_verdict(result)

    def _update(self, current: Calibration | None) -> Calibration:
        result: StationsResult = self.solve.result
        return service.merge_stations(self.base(current), result, self.serial)


class GroundWizard(_SessionWizard):
    def __init__(
        self,
        calibration_path: Path,
        stream: FrameStream | None = None,
        serial: str | None = None,
        parent: QtWidgets.QWidget | None = None,
        ui_state: UiState | None = None,
    ) -> None:
        super().__init__(
            "Calibrate the ground", calibration_path, None, stream, serial, parent, ui_state
        )
        self._add_pages(
            PreparePage("What to prepare", GROUND_TEXT),
            SolvePage(self._solve, self._describe),
            SavePage(calibration_path, self._update),
        )

    def _solve(self) -> Callable[[], GroundResult]:
        return service.ground_job(self.session, self.base(self.in_force()))

    def _describe(self, result: GroundResult) -> tuple[list[str], Verdict]:
        lines = [
            f"station {result.station}: camera {result.camera_height_m:.3f} m above the ground, "
            f"pitched {result.camera_pitch_deg:.1f} degrees down",
            f"ground plane: {100 * result.inlier_fraction:.0f} % of {result.points} points, "
            f"RMS {1000 * result.rms_m:.1f} mm",
            *[f"warning: {w}" for w in result.warnings],
        ]
        if result.change_from_previous is not None:
            moved, tilt = result.change_from_previous
            lines.append(
                f"change from the ground in force: {100 * moved:.1f} cm, {tilt:.2f} degrees"
            )
        return lines, ground_verdict(result)

    def _update(self, current: Calibration | None) -> Calibration:
        result: GroundResult = self.solve.result
        return service.merge_ground(self.base(current), result, self.serial)
