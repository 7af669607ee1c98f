"""Intrinsics against OpenCV's published calibration of its real chessboard photographs."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from fieldapp.calib.board import Board, corner_zero_is_dark, detect_corners
from fieldapp.calib.intrinsics import calibrate_intrinsics, read_calibration_image
from fieldapp.cli import main
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import load_calibration

BOARD = Board(9, 6, 25.0)


@pytest.fixture(scope="module")
def chessboard(shared_data: Path) -> tuple[list[Path], dict]:
    folder = shared_data / "opencv-chessboard"
    text = (folder / "left_intrinsics.yml").read_text().replace("%YAML:1.0", "")
    published = yaml.safe_load(text.replace("!!opencv-matrix", ""))
    return sorted(folder.glob("left*.jpg")), published


def test_matches_opencvs_published_result(chessboard):
    files, published = chessboard
    images = [(p.name, read_calibration_image(p)) for p in files]
    result = calibrate_intrinsics(images, BOARD, fix_aspect=True)
    K = np.array(published["camera_matrix"]["data"]).reshape(3, 3)
    k = result.intrinsics
    assert len(result.used) == published["nframes"] == 13
    assert k.fx == pytest.approx(K[0, 0], rel=1e-3)
    assert k.cx == pytest.approx(K[0, 2], rel=1e-3)
    assert k.cy == pytest.approx(K[1, 2], rel=1e-3)
    assert k.fy == k.fx
    assert result.rms_px == pytest.approx(published["avg_reprojection_error"], abs=0.01)
    np.testing.assert_allclose(
        k.distortion, published["distortion_coefficients"]["data"], atol=0.01
    )
    errors = np.array([v.error_px for v in result.used])
    published_errors = np.array(published["per_view_reprojection_errors"]["data"])
    np.testing.assert_allclose(errors, published_errors, atol=0.02)


def test_cli_prints_figures_and_keeps_the_previous_file(chessboard, tmp_path, capsys):
    files, _ = chessboard
    out = tmp_path / "calibration.json"
    args = ["calibrate", "intrinsics", *map(str, files), "--board", "9x6", "--square-mm", "25"]
    assert main([*args, "--fix-aspect", "--out", str(out), "--serial", "KV2-0042"]) == 0
    text = capsys.readouterr().out
    for word in ("fx 535.9", "cx 342.2", "cy 235.5", "distortion", "RMS reprojection error 0.39"):
        assert word in text
    assert "left02.jpg: 1.18" in text
    saved = load_calibration(out)
    assert saved.depth_camera.width == 640
    assert saved.depth_camera.calibrated["rig_serial"] == "KV2-0042"  # type: ignore[attr-defined]
    assert main([*args[:5], "--board", "9x6", "--square-mm", "25", "--out", str(out)]) == 0
    assert "previous kept as" in capsys.readouterr().out
    assert len(list(tmp_path.glob("calibration.previous-*.json"))) == 1


def test_too_few_good_views_warns(chessboard):
    files, _ = chessboard
    images = [(p.name, read_calibration_image(p)) for p in files[:6]]
    result = calibrate_intrinsics(images, BOARD, fix_aspect=True)
    assert any("only 6 good views" in w for w in result.warnings)


def test_no_board_anywhere_names_the_images_and_mentions_inkjet(capsys, tmp_path):
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640), 128, np.uint8))
    code = main(
        [
            "calibrate",
            "intrinsics",
            str(blank),
            "--board",
            "9x6",
            "--square-mm",
            "25",
            "--out",
            str(tmp_path / "c.json"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 1
    assert "blank.png" in err
    assert "inkjet" in err
    assert not (tmp_path / "c.json").exists()


def test_wrong_board_size_is_not_found(chessboard):
    files, _ = chessboard
    images = [(p.name, read_calibration_image(p)) for p in files[:3]]
    with pytest.raises(FieldappError, match="no 10 x 6 board found"):
        calibrate_intrinsics(images, Board(10, 6, 25.0))


def test_too_few_views(chessboard):
    files, _ = chessboard
    images = [(p.name, read_calibration_image(p)) for p in files[:2]]
    with pytest.raises(FieldappError, match="only 2 image"):
        calibrate_intrinsics(images, BOARD)


def test_outlier_view_rejected_with_reason(chessboard):
    files, _ = chessboard
    images = [(p.name, read_calibration_image(p)) for p in files]
    result = calibrate_intrinsics(images, BOARD, fix_aspect=True, max_view_error_px=1.0)
    rejected = [v for v in result.views if v.rejected]
    assert [v.name for v in rejected] == ["left02.jpg"]
    assert "reprojection error 1.1" in (rejected[0].rejected or "")
    assert result.rms_px < 0.3


@pytest.mark.parametrize(("text", "message"), [("9", "COLSxROWS"), ("2x6", "at least 3 x 3")])
def test_board_option_errors(text, message):
    with pytest.raises(FieldappError, match=message):
        Board.parse(text, 25.0)


def board_image(board: Board, square_px: int, turn_half: bool) -> np.ndarray:
    """A synthetic print of ``board`` (white margin), optionally turned by 180 degrees."""
    squares = np.indices((board.rows + 1, board.cols + 1)).sum(axis=0) % 2
    image = np.where(squares == 0, 30, 225).astype(np.uint8)
    image = np.kron(image, np.ones((square_px, square_px), np.uint8))
    image = np.pad(image, square_px, constant_values=225)
    image = cv2.GaussianBlur(image, (3, 3), 0.8)
    return np.ascontiguousarray(np.rot90(image, 2)) if turn_half else image


def test_corner_order_check_tells_a_half_turn_on_an_asymmetric_board():
    assert not BOARD.is_symmetric
    assert Board(8, 6, 25).is_symmetric
    upright, turned = board_image(BOARD, 24, False), board_image(BOARD, 24, True)
    corners_a, corners_b = detect_corners(upright, BOARD), detect_corners(turned, BOARD)
    assert corners_a is not None
    assert corners_b is not None
    dark_a = corner_zero_is_dark(upright, corners_a, BOARD)
    dark_b = corner_zero_is_dark(turned, corners_b, BOARD)
    assert dark_a is not None
    assert dark_b is not None
    # corners of the turned print in the upright print's order: compare corner 0's positions
    center = np.array(upright.shape[::-1]) - 1
    same_order = np.allclose(center - corners_b[0], corners_a[0], atol=1.0)
    assert (dark_a == dark_b) == same_order


def test_sixteen_bit_ir_is_detected():
    image = board_image(BOARD, 20, False).astype(np.uint16) * 40 + 500
    assert detect_corners(image, BOARD) is not None


def test_saving_twice_in_one_second_keeps_both_previous_files(tmp_path):
    from fieldapp.calib.store import save_keeping_previous
    from fieldapp.io.calibration import CALIBRATION_FORMAT, Calibration, DepthCamera

    camera = DepthCamera(width=4, height=3, fx=1.0, fy=1.0, cx=2.0, cy=1.5)
    path = tmp_path / "rig.json"
    for fx in (1.0, 2.0, 3.0):
        camera.fx = fx
        save_keeping_previous(path, Calibration(format=CALIBRATION_FORMAT, depth_camera=camera))
    kept = sorted(tmp_path.glob("rig.previous-*.json"))
    assert [load_calibration(p).depth_camera.fx for p in kept] == [1.0, 2.0]
