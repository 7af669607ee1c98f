"""Each calibration wizard on a simulated checkerboard session: the happy path to a saved
calibration (checked against the simulator's truth), and its failure states."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets

from devices.geometry import pose_error
from fieldapp.calib.board import Board
from fieldapp.io.calibration import load_calibration
from ui.calibration import CalibratePage
from ui.calibration.intrinsics_wizard import IntrinsicsWizard
from ui.calibration.page import WIZARDS, summary
from ui.calibration.pictures import rms_px
from ui.calibration.session_wizards import ViewsWizard
from ui.calibration.workspace import Workspace
from ui.state import UiState

Back = QtWidgets.QWizard.WizardButton.BackButton
Finish = QtWidgets.QWizard.WizardButton.FinishButton


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
    wizard.resize(1000, 720)  # the pictures scale to the room they have, never grow it
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
    QtWidgets.QApplication.processEvents()  # the layout settles with the pictures shown
    assert (wizard.width(), wizard.height()) == (1000, 720)
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


def _finish(page, wizard):
    """Save on the last step and Finish: back to the overview, the wizard closed."""
    wizard.next()
    wizard.save.save()
    wizard.button(Finish).click()
    assert page.currentWidget() is page.overview
    assert not any(w is wizard for w in page.wizards.values())


def test_view_station_and_ground_wizards_chain_into_one_calibration(
    qtbot, boards_session, tmp_path
):
    """The three session wizards, each opened as a page of the Calibrate area."""
    path = tmp_path / "rig.json"
    truth = _truth(boards_session)
    remembered = UiState(tmp_path / "ui.ini")  # the session folder, across the wizards
    page = CalibratePage(path, ui_state=remembered)
    qtbot.addWidget(page)
    page.show()
    assert "none chosen yet" in page.session.text()
    stations = page.open_wizard("stations")  # opened first, left on its empty session step
    stations.next()
    assert not stations.session_page.isComplete()
    page.show_overview()
    views = page.open_wizard("views")
    views.board_form.square_mm.setValue(VIEW_BOARD.square_mm)
    views.next()
    views.session_page.load(boards_session)
    views.next()
    space = page.currentWidget()  # the solve runs on: Back is off, the steps say so
    assert views.solving and not views.button(Back).isEnabled()
    assert "(solving...)" in space.steps.item(2).text() and space.step_index() == 2
    space.back_button.click()  # to the overview while it solves: the solve is kept
    assert page.currentWidget() is page.overview and page.wizard is None
    assert "continue: step 3 of 4" in page.buttons["views"].text()
    assert "(solving...)" in page.buttons["views"].text()
    assert str(boards_session) in page.session.text()  # the folder, remembered
    assert views.solve.wait(60)
    assert "(solving..." not in page.buttons["views"].text()
    assert page.open_wizard("views") is views and page.wizard is views
    solve = views.solve
    assert 1000 * solve.result.rmse_m < 3.0
    assert abs(solve.result.angle_deg) == pytest.approx(45.0, abs=0.1)
    assert views.button(Back).isEnabled()
    _finish(page, views)
    assert "View step (turntable): calibrated" in page.state.text()
    assert page.open_wizard("stations") is stations  # the folder chosen meanwhile: loaded
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
    _finish(page, stations)
    ground = page.open_wizard("ground")
    ground.next()
    assert ground.session_page.session is not None
    solved = _solve(ground).result
    T_field_camera5 = np.array(truth["T_field_camera"]["5"])
    assert solved.camera_height_m == pytest.approx(T_field_camera5[2, 3], abs=0.02)
    _finish(page, ground)
    saved = load_calibration(path)
    assert saved.view_step is not None and saved.stations is not None and saved.ground is not None
    assert len(list(tmp_path.glob("rig.previous-*.json"))) == 2
    text = summary(path)  # section names in words, not code identifiers
    assert "View step (turntable): calibrated" in text and "Ground plane: calibrated" in text
    assert "Depth camera (intrinsics): nominal" in text
    assert not any(name in text for name in ("depth_camera", "view_step", "ground:"))
    assert page.state.text().endswith(text.split("\n", 1)[1])


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


def test_calibrate_page_opens_each_wizard_as_a_page(qtbot, tmp_path):
    page = CalibratePage(tmp_path / "rig.json", ui_state=UiState(tmp_path / "ui.ini"))
    qtbot.addWidget(page)
    page.show()
    page.activateWindow()  # for the Alt+Left shortcut
    qtbot.waitUntil(lambda: QtWidgets.QApplication.activeWindow() is page, timeout=90_000)
    assert "no calibration yet" in page.state.text()
    alt_left = QtCore.Qt.Key.Key_Left, QtCore.Qt.KeyboardModifier.AltModifier
    for key in ("intrinsics", "views", "stations", "ground"):
        wizard = page.open_wizard(key)
        space = page.currentWidget()
        assert isinstance(space, Workspace) and space.wizard is wizard is page.wizard
        assert wizard.isVisible() and not wizard.isWindow()  # in the page, not a dialog
        assert space.steps.count() == len(wizard.pageIds())
        assert space.steps.item(0).font().bold() and "step 1 of" in space.step.text()
        qtbot.keyClick(wizard, QtCore.Qt.Key.Key_Escape)  # Esc is STOP: never closes it
        assert page.wizard is wizard and wizard.isVisible()
        wizard.next()
        assert space.step_index() == 1 and space.steps.item(1).font().bold()
        qtbot.keyClick(wizard.currentPage(), *alt_left)  # the wizard's Back, then the overview
        assert wizard.currentId() == wizard.pageIds()[0] and page.wizard is wizard
        qtbot.keyClick(wizard.currentPage(), *alt_left)
        assert page.currentWidget() is page.overview and key in page.wizards
        assert "continue: step 1 of" in page.buttons[key].text()
    assert page.open_wizard("views") is page.wizards["views"]  # the same one, as left
    assert len(page.wizards) == 4
    for key, wizard in page.wizards.items():
        page.open_wizard(key)
        wizard.button(QtWidgets.QWizard.WizardButton.CancelButton).click()
        assert key not in page.wizards and page.currentWidget() is page.overview
        assert page.buttons[key].text() == dict((k, t) for k, t, _ in WIZARDS)[key]


def test_a_running_solve_is_not_lost_by_closing(qtbot, boards_session, tmp_path):
    """Cancel, or quitting the window, while a solve runs asks first; No keeps it."""
    page = CalibratePage(tmp_path / "rig.json", ui_state=UiState(tmp_path / "ui.ini"))
    qtbot.addWidget(page)
    page.show()
    wizard = page.open_wizard("intrinsics")
    wizard.next()
    wizard.capture.add_images(sorted((boards_session / "intrinsics").glob("*.png"))[:3])
    wizard.next()
    asked: list[str] = []
    wizard.ask = page.ask = lambda question: asked.append(question) or False
    assert wizard.solving
    wizard.button(QtWidgets.QWizard.WizardButton.CancelButton).click()
    assert not page.confirm_close(page)
    assert "A solve is running" in asked[0] and "Camera intrinsics" in asked[1]
    assert page.wizard is wizard and wizard.isVisible()  # kept, and the solve with it
    assert wizard.solve.wait(60) and wizard.solve.result is not None
    assert page.confirm_close(page) and len(asked) == 2  # nothing to lose: no question
    wizard.ask = lambda question: asked.append(question) or True
    wizard.back()
    wizard.next()  # solving again: Cancel, agreed, waits for it and closes
    wizard.reject()
    assert not page.wizards and len(asked) == 3 and wizard.solve.worker is None
