"""Each calibration wizard on a simulated checkerboard session: the happy path to a saved
calibration (checked against the simulator's truth), and its failure states."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtWidgets

from devices.geometry import pose_error
from fieldapp.calib.board import Board
from fieldapp.io.calibration import load_calibration
from ui.calibration import CalibratePage
from ui.calibration.intrinsics_wizard import IntrinsicsWizard
from ui.calibration.page import summary
from ui.calibration.pictures import rms_px
from ui.calibration.session_wizards import GroundWizard, StationsWizard, ViewsWizard
from ui.state import UiState

Next = QtWidgets.QWizard.WizardButton.NextButton


def _solve(wizard):
    """Move on to the solve page and wait for it."""
    while wizard.currentPage() is not wizard.solve:
        wizard.next()
    assert wizard.solve.wait(60)
    return wizard.solve


def _truth(session: Path) -> dict:
    return json.loads((session / "truth.json").read_text())


def test_intrinsics_wizard_to_a_saved_calibration(qtbot, boards_session, tmp_path):
    wizard = IntrinsicsWizard(tmp_path / "rig.json", serial="SIM-1")
    qtbot.addWidget(wizard)
    wizard.show()
    wizard.next()
    page = wizard.capture
    assert not page.isComplete()
    images = sorted((boards_session / "intrinsics").glob("*.png"))
    refused = page.add_images(images)  # a steeply tilted view may be missed
    assert len(refused) <= 1 and len(page.views) == len(images) - len(refused)
    assert page.isComplete() and page.coverage.counts.sum() == 54 * len(page.views)
    page.listing.setCurrentRow(1)  # an added image, shown with its corners
    name, image, corners = page.views[1]
    assert page.preview.image is image and page.preview.corners is corners
    assert name in page.status.text() and "Board found: 54 corners" in page.preview.state.text()
    count = len(page.views)
    page.remove(1)  # and removed
    assert len(page.views) == page.listing.count() == count - 1
    assert name not in [n for n, _, _ in page.views]
    assert page.coverage.counts.sum() == 54 * len(page.views)
    solve = _solve(wizard)
    result = solve.result
    truth = _truth(boards_session)["intrinsics"]
    assert result.intrinsics.fx == pytest.approx(truth["fx"], rel=0.005)
    assert result.intrinsics.cy == pytest.approx(truth["cy"], abs=2.0)
    assert solve.verdict.text().startswith(("Good", "Usable"))
    picture = wizard.reprojection  # per-view error bars and the reprojection overlay
    timed = [v for v in result.views if v.error_px is not None]
    assert list(picture.bar_item.opts["height"]) == pytest.approx([v.error_px for v in timed])
    assert picture.rms_line.value() == pytest.approx(result.rms_px)
    worst = max(timed, key=lambda v: v.error_px)
    assert picture.choice.count() == len(timed) and worst.name in picture.choice.currentText()
    assert not picture.picture.pixmap().isNull() and worst.name in picture.caption.text()
    for view in timed:  # the corners reprojected through the solved lens
        found = picture.reprojection_of(view.name)
        assert found is not None
        assert rms_px(found[1], found[2]) == pytest.approx(view.error_px, abs=0.05)
    wizard.next()
    wizard.save.save()
    saved = load_calibration(tmp_path / "rig.json")
    assert saved.depth_camera.fx == pytest.approx(result.intrinsics.fx)
    assert saved.depth_camera.calibrated["rig_serial"] == "SIM-1"
    wizard.save.save()  # again: the first file is kept
    assert len(list(tmp_path.glob("rig.previous-*.json"))) == 1
    wizard.close()


def test_intrinsics_refuses_images_without_the_board(qtbot, boards_session, tmp_path):
    wizard = IntrinsicsWizard(tmp_path / "rig.json")
    qtbot.addWidget(wizard)
    wizard.show()
    wizard.board_form.cols.setValue(11)  # an 11 x 6 board is not what was printed
    wizard.next()
    page = wizard.capture
    images = sorted((boards_session / "intrinsics").glob("*.png"))[:2]
    assert page.add_images(images) == [p.name for p in images]
    assert "Board not found" in page.status.text() and not page.isComplete()
    assert page.preview.wait()
    qtbot.waitUntil(lambda: page.preview.image is not None, timeout=90_000)  # a hang limit
    assert not page.preview.found and "BOARD NOT FOUND" in page.preview.state.text()
    assert page.preview.state.wordWrap()  # the whole advice shows, never cut off
    assert not page.take()
    assert "nothing taken" in page.status.text()
    wizard.close()


def test_intrinsics_too_few_views_is_a_redo(qtbot, boards_session, tmp_path):
    wizard = IntrinsicsWizard(tmp_path / "rig.json")
    qtbot.addWidget(wizard)
    wizard.show()
    wizard.next()
    images = sorted((boards_session / "intrinsics").glob("*.png"))[:3]
    wizard.capture.add_images(images)
    solve = _solve(wizard)
    assert solve.result is not None
    assert "only 3 good views" in solve.verdict.text()
    assert solve.verdict.styleSheet() != "" and "Redo" in solve.verdict.text()
    wizard.close()


VIEW_BOARD = Board(9, 6, 50.0)


def _views(qtbot, boards_session, path, board=VIEW_BOARD, ui_state=None):
    wizard = ViewsWizard(path, ui_state=ui_state)
    qtbot.addWidget(wizard)
    wizard.show()
    wizard.board_form.cols.setValue(board.cols)
    wizard.board_form.square_mm.setValue(board.square_mm)
    wizard.next()
    wizard.session_page.load(boards_session)
    return wizard


def test_view_station_and_ground_wizards_chain_into_one_calibration(
    qtbot, boards_session, tmp_path
):
    path = tmp_path / "rig.json"
    truth = _truth(boards_session)
    remembered = UiState(tmp_path / "ui.ini")  # the session folder, across the wizards
    views = _views(qtbot, boards_session, path, ui_state=remembered)
    solve = _solve(views)
    assert 1000 * solve.result.rmse_m < 3.0
    assert abs(solve.result.angle_deg) == pytest.approx(45.0, abs=0.1)
    views.next()
    views.save.save()
    views.close()
    stations = StationsWizard(path, ui_state=remembered)
    qtbot.addWidget(stations)
    stations.show()
    stations.next()  # the folder the views wizard loaded is loaded again: nothing retyped
    assert stations.session_page.folder.text() == str(boards_session)
    assert stations.session_page.isComplete()
    result = _solve(stations).result
    T_true = np.linalg.inv(np.array(truth["T_field_camera"]["5"])) @ np.array(
        truth["T_field_camera"]["4"]
    )
    moved_m, turned_deg = pose_error(result.T_reference_station[4], T_true)
    assert moved_m < 0.01 and turned_deg < 0.5
    T_field_reference = load_calibration(path).ground.matrix  # the top view is levelled
    layout_view = stations.layout_view
    for station in (4, 5):
        field = (T_field_reference @ result.T_reference_station[station])[:2, 3]
        assert layout_view.positions[station] == pytest.approx(tuple(field))
    assert "field x" in layout_view.getAxis("bottom").labelText
    figures = stations.solve.figures.toPlainText()  # the frame and axes named, in metres
    assert "reference frame (station 5's camera at view 0: x right, y down, z forward)" in figures
    x, y, z = result.T_reference_station[4][:3, 3]
    assert f"station 4 (joined through station 5): x {x:+.3f} m, y {y:+.3f} m, z {z:+.3f} m" in (
        figures
    )
    stations.next()
    stations.save.save()
    stations.close()
    ground = GroundWizard(path, ui_state=remembered)
    qtbot.addWidget(ground)
    ground.show()
    ground.next()
    assert ground.session_page.session is not None
    solved = _solve(ground).result
    T_field_camera5 = np.array(truth["T_field_camera"]["5"])
    assert solved.camera_height_m == pytest.approx(T_field_camera5[2, 3], abs=0.02)
    ground.next()
    ground.save.save()
    ground.close()
    saved = load_calibration(path)
    assert saved.view_step is not None and saved.stations is not None and saved.ground is not None
    assert len(list(tmp_path.glob("rig.previous-*.json"))) == 2
    text = summary(path)  # section names in words, not code identifiers
    assert "View step (turntable): calibrated" in text and "Ground plane: calibrated" in text
    assert "Depth camera (intrinsics): nominal" in text
    assert not any(name in text for name in ("depth_camera", "view_step", "ground:"))


def test_views_wizard_without_the_board_says_so(qtbot, boards_session, tmp_path):
    wizard = _views(qtbot, boards_session, tmp_path / "rig.json", Board(11, 6, 50.0))
    solve = _solve(wizard)
    assert solve.result is None and not solve.isComplete()
    assert "no 11 x 6 board found" in solve.status.text()
    assert solve.verdict.text().startswith("Redo")
    wizard.close()


def test_session_page_refuses_a_folder_that_is_not_a_session(qtbot, tmp_path):
    wizard = ViewsWizard(tmp_path / "rig.json")
    qtbot.addWidget(wizard)
    wizard.show()
    wizard.next()
    wizard.session_page.folder.setText(str(tmp_path))
    wizard.session_page._try(lambda: wizard.session_page.load(tmp_path))
    assert "session.json" in wizard.session_page.status.text()
    assert not wizard.session_page.isComplete()
    wizard.close()


def test_calibrate_page_opens_each_wizard(qtbot, tmp_path):
    page = CalibratePage(tmp_path / "rig.json")
    qtbot.addWidget(page)
    assert "no calibration yet" in page.state.text()
    for key in ("intrinsics", "views", "stations", "ground"):
        wizard = page.open_wizard(key)
        assert wizard.isVisible()
        wizard.reject()
        assert page.wizard is None
