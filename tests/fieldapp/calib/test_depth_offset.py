"""A depth camera's static offset (a Kinect v2 unit adds 1-4 cm to every depth), found from
the boards by ``fieldapp calibrate views`` and taken off every depth read."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from devices.geometry import make_transform, pose_error, rotation_x, rotation_y, transform_points
from fieldapp.calib import service
from fieldapp.calib.board import Board
from fieldapp.calib.corners3d import Corners3D
from fieldapp.calib.depth_offset import board_offset_m
from fieldapp.calib.views import calibrate_view_step
from fieldapp.cli import main
from fieldapp.io.calibration import DepthCamera
from fieldapp.io.images import depth_units_to_m
from fieldapp.io.session import Session, load_session

BOARD = Board(9, 6, 50.0)


def _lifted(offset_m: float, tilt: tuple[float, float], board: Board = BOARD) -> Corners3D:
    """``board``'s corners 1.5 m away, turned by ``tilt`` (degrees about y and x), lifted with
    depth ``offset_m`` too far (each moved along its viewing ray)."""
    T = make_transform(rotation_y(tilt[0]) @ rotation_x(tilt[1]), np.array([0.1, -0.05, 1.5]))
    true = transform_points(T, board.object_points_m())
    lifted = true / true[:, 2:3] * (true[:, 2:3] + offset_m)
    return Corners3D(lifted, np.ones(len(true)))


@pytest.mark.parametrize("offset_m", [0.03, -0.02, 0.0])
@pytest.mark.parametrize("tilt", [(0.0, 0.0), (20.0, 30.0), (-10.0, 50.0)])
def test_a_boards_corners_tell_the_offset_they_were_lifted_with(
    offset_m: float, tilt: tuple[float, float]
) -> None:
    found = board_offset_m(_lifted(offset_m, tilt), BOARD)
    assert found == pytest.approx(offset_m, abs=1e-4)


def test_a_board_of_another_size_or_too_few_corners_tells_nothing() -> None:
    other = _lifted(0.03, (10.0, 20.0), Board(9, 6, 40.0))  # told 50 mm, printed 40 mm
    assert board_offset_m(other, BOARD) is None
    sparse = _lifted(0.03, (10.0, 20.0))
    sparse.weights[11:] = 0.0  # 11 corners lifted
    assert board_offset_m(sparse, BOARD) is None


def test_the_offset_is_taken_off_every_depth_read() -> None:
    units = np.array([[0, 1500], [2000, 65535]], np.uint16)
    plain = DepthCamera(width=2, height=2, fx=1.0, fy=1.0, cx=0.0, cy=0.0)
    assert np.array_equal(plain.metres(units), depth_units_to_m(units, 1000.0), equal_nan=True)
    offset = plain.model_copy(update={"depth_offset_m": 0.03})
    metres = offset.metres(units)
    assert np.isnan(metres[0, 0])  # no measurement stays none
    assert metres[0, 1] == pytest.approx(1.47) and metres[1, 0] == pytest.approx(1.97)


@pytest.fixture(scope="module")
def offset_boards(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("offset") / "boards"
    options = ["--scene", "checkerboard", "--stations", "4,5", "--seed", "3"]
    assert main(["simulate", "--out", str(folder), *options, "--depth-offset", "0.03"]) == 0
    return folder


def _as_recorded(folder: Path) -> Session:
    """The boards as a rig whose calibration knows no offset recorded them."""
    session = load_session(folder)
    assert session.calibration.depth_camera.depth_offset_m == 0.03  # the simulator's truth
    camera = session.calibration.depth_camera.model_copy(update={"depth_offset_m": None})
    return replace(
        session, calibration=session.calibration.model_copy(update={"depth_camera": camera})
    )


@pytest.mark.slow
def test_the_view_step_solve_finds_the_offset_and_solves_without_it(offset_boards: Path) -> None:
    session = _as_recorded(offset_boards)
    result = calibrate_view_step(session, BOARD)
    assert result.depth_offset is not None and result.depth_offset.boards >= 4
    assert result.depth_offset.offset_m == pytest.approx(0.03, abs=0.002)
    nominal = session.calibration.view_step
    assert nominal is not None
    moved_m, turned_deg = pose_error(result.T_view_k_view_k1, nominal.matrix)
    assert moved_m < 0.002 and turned_deg < 0.1
    assert result.rmse_m < 0.0015  # 3 cm too far, the corners fitted 2-3 times worse
    merged = service.merge_view_step(session.calibration, result, 45.0, None)
    assert merged.depth_camera.depth_offset_m == pytest.approx(0.03, abs=0.002)
    provenance = merged.view_step.calibrated if merged.view_step else None
    assert provenance is not None and provenance["depth_offset_boards"] >= 4  # type: ignore[typeddict-item]


def test_the_simulator_writes_the_offset_into_its_nominal_calibration(tmp_path: Path) -> None:
    out = tmp_path / "offset"
    options = ["--stations", "5", "--views", "0", "--depth-offset", "-0.02"]
    assert main(["simulate", "--out", str(out), *options]) == 0
    calibration = json.loads((out / "calibration.json").read_text())
    assert calibration["depth_camera"]["depth_offset_m"] == -0.02
    assert json.loads((out / "truth.json").read_text())["depth_offset_m"] == -0.02


def test_the_simulator_refuses_offsets_beyond_5_cm(simulate_refuses) -> None:
    simulate_refuses(
        "--depth-offset", [("0.06", "--depth-offset"), ("-1", "--depth-offset"), ("x", "number")]
    )
