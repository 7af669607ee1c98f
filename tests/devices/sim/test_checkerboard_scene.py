"""The calibration scenes: boards seen where the calibration workflows need them, tagged."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from devices.camera.frames import KINECT_V2_PAPER
from devices.geometry import invert, transform_points
from devices.sim.calibration_scenes import checkerboard_scene, neighbour_pairs
from devices.sim.rig import RigGeometry, StopErrors
from devices.sim.world import SimWorld
from fieldapp.cli import main
from fieldapp.io.images import read_ir
from fieldapp.io.session import load_session


def test_neighbour_pairs_of_the_3_by_3_grid() -> None:
    pairs = neighbour_pairs()
    assert len(pairs) == 12 and (4, 5) in pairs and (2, 5) in pairs and (3, 4) not in pairs


def test_every_board_is_seen_where_calibration_needs_it() -> None:
    rig = RigGeometry()
    world = SimWorld(checkerboard_scene(0, rig), rig)
    seen: dict[str, set[tuple[int, int]]] = {}
    for station in range(1, 10):
        _, pose = StopErrors().base_stop(rig.station_pose(station), np.random.default_rng(station))
        world.set_base_pose(pose.x_m, pose.y_m, pose.yaw_deg)
        for view in range(8):
            world.set_table_angle_deg(45.0 * view)
            for name in world.boards_in_view():
                seen.setdefault(name, set()).add((station, view))
    assert {(5, 0), (5, 1)} <= seen["view-step"]
    for a, b in neighbour_pairs():
        stations = {s for s, _ in seen[f"stations-{a}-{b}"]}
        assert {a, b} <= stations, f"board {a}-{b} seen only from {sorted(stations)}"


def detect(ir: np.ndarray, size: tuple[int, int]) -> np.ndarray | None:
    gray = np.clip(np.sqrt(ir / max(float(ir.max()), 1.0)) * 255, 0, 255).astype(np.uint8)
    found, corners = cv2.findChessboardCorners(gray, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    return cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), criteria).reshape(-1, 2)


@pytest.mark.slow
def test_checkerboard_session_tags_captures_and_records_boards(tmp_path: Path) -> None:
    out = tmp_path / "boards"
    options = ["--scene", "checkerboard", "--stations", "5", "--views", "0,1"]
    assert main(["simulate", "--out", str(out), *options, "--intrinsics-images", "2"]) == 0
    session = load_session(out)
    truth = json.loads((out / "truth.json").read_text())
    keys = {c.key for c in session.captures}
    assert {(5, 0, None), (5, 1, None), (5, 0, "view-step"), (5, 1, "view-step")} <= keys
    assert (5, 0, "stations-5-6") in keys  # the board towards station 6 lies ahead of view 0
    boards = {b["name"]: b for b in truth["boards"]}
    assert {"view-step", "intrinsics"} | {f"stations-{a}-{b}" for a, b in neighbour_pairs()} <= set(
        boards
    )
    # the board is in the IR image exactly where its true pose puts it
    poses = {(c["station"], c["view"], c["target"]): c["T_field_camera"] for c in truth["captures"]}
    board = boards["view-step"]
    for view in (0, 1):
        capture = next(c for c in session.captures if c.key == (5, view, "view-step"))
        assert capture.ir is not None
        corners = detect(read_ir(out / capture.ir), (board["inner_cols"], board["inner_rows"]))
        assert corners is not None
        camera = transform_points(
            invert(np.array(poses[(5, view, "view-step")])), np.array(board["corners_field_m"])
        )
        projected, _ = cv2.projectPoints(camera, np.zeros(3), np.zeros(3), KINECT_V2_PAPER.K, None)
        error_px = np.linalg.norm(corners - projected.reshape(-1, 2), axis=1)
        assert np.median(error_px) < 0.5
    images = truth["intrinsics_images"]["images"]
    assert len(images) == 2
    ir = read_ir(out / images[0]["ir"])
    assert ir.shape == (424, 512) and ir.max() > 1000
