"""A simulated session back-projected with the true poses of truth.json reproduces the truth."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

from fieldapp.cli import main
from fieldapp.io.session import Session, load_session

pytestmark = pytest.mark.slow


def simulate(folder: Path, *options: str) -> tuple[Session, dict[str, Any]]:
    assert main(["simulate", "--out", str(folder), *options]) == 0
    return load_session(folder), json.loads((folder / "truth.json").read_text())


def field_points(session: Session, truth: dict[str, Any]) -> np.ndarray:
    """(N, 3) every measured point in the field frame, using each capture's true pose."""
    camera = session.calibration.depth_camera
    v, u = np.mgrid[0 : camera.height, 0 : camera.width]
    rays = np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(u.shape)], -1
    )
    rays = rays.reshape(-1, 3)
    poses = {(c["station"], c["view"]): np.array(c["T_field_camera"]) for c in truth["captures"]}
    clouds = []
    for images in session.iter_captures():
        depth = images.depth_m.reshape(-1).astype(np.float64)
        seen = np.isfinite(depth)
        T = poses[(images.capture.station, images.capture.view)]
        clouds.append((rays[seen] * depth[seen, None]) @ T[:3, :3].T + T[:3, 3])
    return np.concatenate(clouds)


def robust_top_m(points: np.ndarray) -> float:
    """Highest point with at least 8 neighbours within 1 cm (no isolated flying pixels)."""
    neighbours = cKDTree(points).query_ball_point(points, 0.01, return_length=True)
    return float(points[neighbours >= 8, 2].max())


def test_plant_heights_from_back_projection_match_the_truth(tmp_path: Path) -> None:
    session, truth = simulate(tmp_path / "plot", "--seed", "3", "--views", "0,2,4,6")
    assert len(session.captures) == 36 and len(truth["plants"]) == 16
    points = field_points(session, truth)
    points = points[(np.abs(points[:, :2]) < 2.0).all(axis=1)]  # the plot
    index = cKDTree(points[:, :2])
    for plant in truth["plants"]:
        radius = plant["width_cm"] / 200 + 0.02
        near = points[index.query_ball_point([plant["x_m"], plant["y_m"]], radius)]
        above = near[near[:, 2] > plant["z_m"] + 0.03]  # the plant, not its soil
        assert len(above) > 1000, plant["name"]
        height_cm = 100 * (robust_top_m(above) - plant["z_m"])
        assert height_cm == pytest.approx(plant["height_cm"], abs=1.5), plant["name"]
        # and the ground around it lies where the truth says
        soil = near[near[:, 2] < plant["z_m"] + 0.03]
        assert np.median(soil[:, 2]) == pytest.approx(plant["z_m"], abs=0.01)


def test_view0_truth_is_the_true_pose_of_each_station(tmp_path: Path) -> None:
    session, truth = simulate(tmp_path / "s", "--stations", "1,5", "--views", "0")
    for capture in truth["captures"]:
        assert truth["T_field_camera"][str(capture["station"])] == capture["T_field_camera"]
    assert truth["T_field_camera"]["1"] != truth["T_field_camera"]["5"]
    assert session.calibration.stations is not None
    assert set(session.calibration.stations.to_reference) == set(range(1, 10))


def test_spheres_are_where_the_truth_says(tmp_path: Path) -> None:
    session, truth = simulate(tmp_path / "spheres", "--scene", "spheres", "--stations", "5")
    points = field_points(session, truth)
    assert len(truth["spheres"]) == 6
    for sphere in truth["spheres"]:
        centre = np.array([sphere["x_m"], sphere["y_m"], sphere["z_m"]])
        radius = sphere["diameter_mm"] / 2000
        distance = np.linalg.norm(points - centre, axis=1)
        on_sphere = distance[np.abs(distance - radius) < 0.02]
        assert len(on_sphere) > 500, sphere["name"]
        assert np.median(on_sphere) == pytest.approx(radius, abs=0.003), sphere["name"]
