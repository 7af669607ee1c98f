"""Calibration against the simulator's ground truth, and each bad input it must refuse."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from devices.geometry import invert, pose_error
from fieldapp.calib.board import Board
from fieldapp.calib.intrinsics import calibrate_intrinsics, read_calibration_image
from fieldapp.calib.observe import Observation, align_order
from fieldapp.calib.stations import calibrate_stations
from fieldapp.calib.views import ViewStepResult, calibrate_view_step
from fieldapp.cli import main
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import load_calibration
from fieldapp.io.session import load_session

VIEW_BOARD = Board(9, 6, 50.0)
STATION_BOARD = Board(9, 6, 40.0)


@pytest.fixture(scope="module")
def boards_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("calibration") / "boards"
    args = ["simulate", "--out", str(folder), "--scene", "checkerboard", "--seed", "7"]
    assert main([*args, "--stations", "4,5,6", "--intrinsics-images", "12"]) == 0
    return folder


@pytest.fixture(scope="module")
def truth(boards_session: Path) -> dict:
    return json.loads((boards_session / "truth.json").read_text())


def _relative_truth(truth: dict, station: int) -> np.ndarray:
    T = {int(k): np.array(v) for k, v in truth["T_field_camera"].items()}
    return invert(T[5]) @ T[station]


def test_intrinsics_from_simulated_ir_within_half_a_percent(boards_session, truth):
    images = [
        (p.name, read_calibration_image(p)) for p in sorted(boards_session.glob("intrinsics/*.png"))
    ]
    result = calibrate_intrinsics(images, STATION_BOARD)
    k, true = result.intrinsics, truth["intrinsics"]
    for name in ("fx", "fy", "cx", "cy"):
        assert getattr(k, name) == pytest.approx(true[name], rel=0.005), name
    assert result.rms_px < 0.3


@pytest.fixture(scope="module")
def view_step(boards_session: Path) -> ViewStepResult:
    """The view step calibrated from the boards (about 10 s: every view's corners found)."""
    return calibrate_view_step(load_session(boards_session), VIEW_BOARD)


def test_view_step_within_a_tenth_of_a_degree_and_2_mm(boards_session, view_step):
    nominal = load_session(boards_session).calibration.view_step
    assert nominal is not None
    moved_m, turned_deg = pose_error(view_step.T_view_k_view_k1, nominal.matrix)
    assert moved_m < 0.002
    assert turned_deg < 0.1
    assert 0.0005 < view_step.rmse_m < 0.005  # the feature RMSE is reported (paper: 1.8 mm)


def test_stations_within_5_mm_and_0_3_degrees(boards_session, truth, view_step):
    session = load_session(boards_session)
    step = session.calibration.view_step.model_copy(update={"matrix": view_step.T_view_k_view_k1})
    prior = session.calibration.stations.to_reference
    result = calibrate_stations(session, STATION_BOARD, step, 5, prior)
    assert sorted(result.T_reference_station) == [4, 5, 6]
    for station in (4, 6):
        moved_m, turned_deg = pose_error(
            result.T_reference_station[station], _relative_truth(truth, station)
        )
        assert moved_m < 0.005, station
        assert turned_deg < 0.3, station
    assert all(p.fit.rmse_m < 0.01 for p in result.pairs)
    # the nominal calibration, which the base never matches, is visibly worse
    assert pose_error(prior[4], _relative_truth(truth, 4))[0] > 0.02
    # where the base reported standing while the boards were captured, for later sessions'
    # reported stops to be measured from (recon/arrival.py)
    reported = {c.station: c.base_pose for c in session.captures if c.base_pose is not None}
    assert sorted(result.base_poses) == [4, 5, 6]
    for station, (x, y, yaw_deg) in result.base_poses.items():
        pose = reported[station]
        assert (x, y, yaw_deg) == pytest.approx((pose.x, pose.y, pose.yaw_deg), abs=1e-9)


def test_the_commands_chain_into_a_usable_calibration(boards_session, tmp_path, capsys, truth):
    out = tmp_path / "rig.json"
    common = ["--board", "9x6", "--serial", "SIM-1"]
    assert (
        main(
            [
                "calibrate",
                "views",
                str(boards_session),
                *common,
                "--square-mm",
                "50",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "calibrate",
                "stations",
                str(boards_session),
                *common,
                "--square-mm",
                "40",
                "--calibration",
                str(out),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "calibrate",
                "ground",
                str(boards_session),
                "--calibration",
                str(out),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "feature point RMSE" in text
    assert "joint refinement" in text
    assert "above the ground" in text
    calibration = load_calibration(out)
    assert calibration.view_step.calibrated["rig_serial"] == "SIM-1"  # type: ignore[union-attr]
    assert calibration.stations is not None and calibration.stations.base_poses is not None
    assert sorted(calibration.stations.base_poses) == [4, 5, 6]
    assert len(list(tmp_path.glob("rig.previous-*.json"))) == 2
    T_field_camera5 = np.array(truth["T_field_camera"]["5"])
    assert calibration.ground is not None
    assert calibration.ground.matrix[2, 3] == pytest.approx(T_field_camera5[2, 3], abs=0.02)
    up_truth, up = T_field_camera5[2, :3], calibration.ground.matrix[2, :3]
    assert np.degrees(np.arccos(np.clip(up_truth @ up, -1, 1))) < 1.5


def _copy(session: Path, tmp_path: Path) -> Path:
    """The session with only station 5's views 0 and 1 (the view-step board's pair)."""
    target = tmp_path / "copy"
    shutil.copytree(session, target)
    document = json.loads((target / "session.json").read_text())
    document["captures"] = [
        c for c in document["captures"] if c["station"] == 5 and c["view"] in (0, 1)
    ]
    for capture in document["captures"]:  # the tests repaint images: no recorded checksums
        capture.pop("sha256", None)
    (target / "session.json").write_text(json.dumps(document))
    return target


def _station5_view(folder: Path, view: int, kind: str) -> list[Path]:
    document = json.loads((folder / "session.json").read_text())
    return [
        folder / c[kind] for c in document["captures"] if c["station"] == 5 and c["view"] == view
    ]


def test_board_seen_in_only_one_view(boards_session, tmp_path):
    folder = _copy(boards_session, tmp_path)
    for path in _station5_view(folder, 1, "color"):
        cv2.imwrite(str(path), np.full((424, 512, 3), 90, np.uint8))
    with pytest.raises(FieldappError, match="only one view of a pair"):
        calibrate_view_step(load_session(folder), VIEW_BOARD, station=5)


def test_depth_missing_at_the_corners(boards_session, tmp_path):
    folder = _copy(boards_session, tmp_path)
    for path in _station5_view(folder, 1, "depth"):
        cv2.imwrite(str(path), np.zeros((424, 512), np.uint16))
    with pytest.raises(FieldappError, match="depth missing at 54 of 54 corners"):
        calibrate_view_step(load_session(folder), VIEW_BOARD, station=5)


def test_no_board_in_any_pair(boards_session, capsys):
    code = main(
        [
            "calibrate",
            "views",
            str(boards_session),
            "--board",
            "7x4",
            "--square-mm",
            "50",
            "--out",
            "/nonexistent/never-written.json",
        ]
    )
    assert code == 1
    assert "no 7 x 4 board found" in capsys.readouterr().err


def _observation(dark: bool | None) -> Observation:
    from fieldapp.calib.corners3d import Corners3D

    grid = np.mgrid[0:9, 0:6].T.reshape(-1, 2).astype(np.float64) * 0.04
    points = np.column_stack([grid, np.full(len(grid), 1.5)])
    return Observation(None, grid.astype(np.float32), dark, Corners3D(points, np.ones(len(grid))))  # type: ignore[arg-type]


def test_corner_order_on_a_symmetric_board_is_not_guessed_from_the_colours():
    """Without a prior, two identical views of an 8 x 6 board: the identity keeps the camera
    upright, its reverse (a half turn about the board's normal, here the optical axis) does not;
    the colours of a symmetric board say nothing."""
    aligned = align_order(_observation(True), _observation(False), Board(8, 6, 40.0))
    assert aligned is not None
    np.testing.assert_array_equal(aligned.corners.points_m, _observation(None).corners.points_m)


def test_flipped_corner_order_is_corrected_when_the_colours_tell():
    a, b = _observation(True), _observation(False)
    aligned = align_order(a, b, VIEW_BOARD)
    assert aligned is not None
    np.testing.assert_array_equal(aligned.corners.points_m, b.corners.points_m[::-1])


def test_corner_order_that_nothing_tells_is_not_guessed():
    assert align_order(_observation(None), _observation(True), VIEW_BOARD) is None
