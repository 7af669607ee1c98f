"""``calibrate intrinsics`` as users call it: folders and globs, unreadable files skipped,
over-exposure named, the principal point and k3 fixed on request."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from fieldapp.calib.board import Board, detect_corners
from fieldapp.calib.image_files import expand_image_paths, read_images
from fieldapp.calib.intrinsics import SolveOptions, calibrate_intrinsics, washed_out_fraction
from fieldapp.cli import main
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import load_calibration

BOARD = Board(9, 6, 25.0)
PUBLISHED_CX, PUBLISHED_CY = 342.28315, 235.57083


@pytest.fixture(scope="module")
def photos(shared_data: Path) -> Path:
    return shared_data / "opencv-chessboard"


@pytest.fixture(scope="module")
def images(photos: Path) -> list[tuple[str, np.ndarray]]:
    return [
        (p.name, cv2.imread(str(p), cv2.IMREAD_UNCHANGED)) for p in sorted(photos.glob("*.jpg"))
    ]


def glare(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """A saturated spot (the sun or the IR emitter's reflection) on the board's centre."""
    corners = detect_corners(image, BOARD)
    assert corners is not None
    cx, cy = corners.mean(axis=0)
    yy, xx = np.mgrid[: image.shape[0], : image.shape[1]]
    spot = 400.0 * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * sigma_px**2))
    return np.clip(image + spot, 0, 255).astype(np.uint8)


def test_a_folder_with_a_zero_byte_bmp_calibrates_and_warns(photos, tmp_path, capsys):
    folder = tmp_path / "ir"
    shutil.copytree(photos, folder)
    (folder / "left15.bmp").write_bytes(b"")
    small = cv2.resize(cv2.imread(str(folder / "left01.jpg")), (320, 240))
    cv2.imwrite(str(folder / "colour.png"), small)  # another camera's image in the folder
    out = tmp_path / "calibration.json"
    args = ["calibrate", "intrinsics", str(folder), "--board", "9x6", "--square-mm", "25"]
    assert main([*args, "--fix-aspect", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "left15.bmp: skipped: empty file" in text
    assert "colour.png: REJECTED: size 320 x 240 differs from the other images' 640 x 480" in text
    assert "over 13 views" in text
    assert load_calibration(out).depth_camera.fx == pytest.approx(535.91573, rel=1e-3)


def test_quoted_glob_and_files_are_expanded_once_in_natural_order(photos):
    paths = expand_image_paths([Path(f"{photos}/left0*.jpg"), photos / "left01.jpg"])
    assert [p.name for p in paths] == [f"left0{i}.jpg" for i in range(1, 10)]
    with pytest.raises(FieldappError, match="the pattern matches no file"):
        expand_image_paths([Path(f"{photos}/right*.jpg")])
    with pytest.raises(FieldappError, match="no such file or folder"):
        expand_image_paths([photos / "missing.png"])


def test_only_unreadable_files_is_an_error_naming_them(tmp_path):
    (tmp_path / "a.png").write_bytes(b"")
    (tmp_path / "b.png").write_bytes(b"not a png")
    with pytest.raises(FieldappError, match=r"a\.png: skipped: empty file\n.*b\.png: skipped"):
        read_images(expand_image_paths([tmp_path]))


def test_a_view_with_corners_on_a_saturated_patch_is_rejected_as_over_exposed(images):
    spoiled = [(n, glare(i, 20.0) if n == "left03.jpg" else i) for n, i in images]
    result = calibrate_intrinsics(spoiled, BOARD, options=SolveOptions(fix_aspect=True))
    reasons = {v.name: v.rejected for v in result.views if v.rejected}
    assert list(reasons) == ["left03.jpg"]
    assert "over-exposed" in reasons["left03.jpg"]
    assert "corners sit on a saturated patch" in reasons["left03.jpg"]


def test_a_board_lost_in_glare_is_named_over_exposed(images):
    spoiled = [(n, glare(i, 60.0) if n == "left05.jpg" else i) for n, i in images]
    result = calibrate_intrinsics(spoiled, BOARD, options=SolveOptions(fix_aspect=True))
    reasons = {v.name: v.rejected for v in result.views if v.rejected}
    assert reasons["left05.jpg"].startswith("board not found;")
    assert "over-exposed?" in reasons["left05.jpg"]


def test_clipped_white_squares_alone_are_not_over_exposure(images):
    """left05 and left08 have a quarter of their board pixels at 255 (the white squares)."""
    for name, image in images:
        corners = detect_corners(image, BOARD)
        assert washed_out_fraction(image, corners, BOARD) == 0.0, name


def test_fixed_principal_point_and_k3(images):
    few = images[:6]
    centre = calibrate_intrinsics(few, BOARD, options=SolveOptions(fix_principal_point=True))
    assert (centre.intrinsics.cx, centre.intrinsics.cy) == pytest.approx((319.5, 239.5))
    given = calibrate_intrinsics(
        few,
        BOARD,
        options=SolveOptions(
            fix_principal_point=True, principal_point=(PUBLISHED_CX, PUBLISHED_CY), fix_k3=True
        ),
    )
    assert given.intrinsics.cx == PUBLISHED_CX and given.intrinsics.cy == PUBLISHED_CY
    assert given.intrinsics.distortion[4] == 0.0
    free = calibrate_intrinsics(few, BOARD)
    assert free.intrinsics.distortion[4] != 0.0


def test_the_options_reach_the_file(photos, tmp_path, capsys):
    out = tmp_path / "c.json"
    args = ["calibrate", "intrinsics", f"{photos}/left*.jpg", "--board", "9x6", "--square-mm", "25"]
    assert (
        main([*args, "--fix-principal-point", "342.28,235.57", "--fix-k3", "--out", str(out)]) == 0
    )
    camera = load_calibration(out).depth_camera
    assert (camera.cx, camera.cy, camera.distortion[4]) == (342.28, 235.57, 0.0)
    assert camera.calibrated["fixed"] == ["principal_point", "k3"]  # type: ignore[attr-defined]
    assert main([*args, "--fix-principal-point", "middle", "--out", str(out)]) == 1
    assert "expected CX,CY" in capsys.readouterr().err
