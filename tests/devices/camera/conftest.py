"""Fixtures of the camera tests: a small simulated world with known geometry, and a
hand-written session folder (written with OpenCV and json only, not the project's writer)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import ndimage

from devices.sim.render import Renderer, SensorModel
from devices.sim.scene import Body, Scene
from devices.sim.world import SimWorld

SPHERE_X_M = 1.5
"""A 400 mm sphere stands here, in front of the camera at table angle 0 (behind it at 180)."""


def flat_ground_scene() -> Scene:
    """A flat grey ground (z = 0, 12 m square) and one foam sphere; no soil relief."""
    half = 6.0
    vertices = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
    triangles = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    ground = Body(
        "ground",
        "soil",
        vertices.astype(np.float64),
        triangles,
        np.full((4, 3), 0.4, np.float32),
        np.full(4, 0.5, np.float32),
    )
    scene = Scene(soil=None, bodies=[ground])
    scene.add_sphere("sphere", SPHERE_X_M, 0.0, 400)
    return scene


@pytest.fixture(scope="session")
def flat_world() -> SimWorld:
    """The flat scene seen by the rig at the reference station, table at 0 degrees."""
    return SimWorld(flat_ground_scene(), seed=3)


@pytest.fixture(scope="session")
def flat_truth(flat_world: SimWorld) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """(noise-free depth at table angle 0, pixels within 2.5 m and 3 px or more from any
    depth edge or missing pixel): where the axial noise alone can be measured."""
    clean = Renderer(flat_world.scene, flat_world.intrinsics, SensorModel(noise=False))
    angle = flat_world.table_angle_deg()
    flat_world.set_table_angle_deg(0.0)
    truth = clean.render(flat_world.T_field_camera()).depth_m
    flat_world.set_table_angle_deg(angle)
    padded = np.pad(truth, 1, mode="edge")
    centre = padded[1:-1, 1:-1]
    neighbours = [padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]]
    with np.errstate(invalid="ignore"):
        jump = np.max([np.abs(n - centre) for n in neighbours], axis=0) > 0.02 * centre
        near = truth < 2.5
    far = ~ndimage.binary_dilation(jump | ~np.isfinite(truth), iterations=3)
    return truth, far & near


def _calibration() -> dict[str, object]:
    eye = np.eye(4).tolist()
    return {
        "format": "fieldapp-calibration/1",
        "depth_camera": {
            "width": 8,
            "height": 6,
            "fx": 10.0,
            "fy": 10.5,
            "cx": 4.0,
            "cy": 3.0,
            "distortion": [0.01, 0, 0, 0, 0],
            "depth_scale": 4000.0,
        },
        "view_step": {"angle_deg": 180.0, "matrix": eye},
        "stations": {"reference": 1, "to_reference": {"1": eye, "2": eye}},
    }


@pytest.fixture
def hand_session(tmp_path: Path) -> Path:
    """A 3-capture session of 8 x 6 images in the spec's format, with its own conventions:
    depth_scale 4000, a JPEG colour image, an RGBA PNG, an IR image, a backslash path, a
    calibration target, and unknown fields. Expected arrays are saved beside it as .npy."""
    folder = tmp_path / "hand"
    (folder / "img").mkdir(parents=True)
    rng = np.random.default_rng(5)
    captures = []
    for index, (station, view) in enumerate([(2, 1), (1, 0), (1, 1)]):
        units = rng.integers(1, 65535, (6, 8)).astype(np.uint16)
        units[index, :3] = 0  # no measurement
        rgb = rng.integers(0, 256, (6, 8, 3)).astype(np.uint8)
        cv2.imwrite(str(folder / f"img/d{index}.png"), units)
        entry: dict[str, object] = {
            "station": station,
            "view": view,
            "depth": f"img/d{index}.png",
            "color": f"img/c{index}.png",
            "future_field": {"x": index},
        }
        if index == 0:
            entry["color"] = "img/c0.jpg"
            cv2.imwrite(str(folder / "img/c0.jpg"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
            rgb = cv2.cvtColor(cv2.imread(str(folder / "img/c0.jpg")), cv2.COLOR_BGR2RGB)
        elif index == 1:
            bgra = np.dstack([rgb[:, :, ::-1], np.full((6, 8), 255, np.uint8)])
            cv2.imwrite(str(folder / "img/c1.png"), bgra)
            ir = rng.integers(0, 65535, (6, 8)).astype(np.uint16)
            cv2.imwrite(str(folder / "img/ir1.png"), ir)
            np.save(folder / "ir1.npy", ir)
            entry["ir"] = "img\\ir1.png"
            entry["target"] = "board-a"
        else:
            cv2.imwrite(str(folder / "img/c2.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        depth_m = units.astype(np.float32) / np.float32(4000.0)
        depth_m[units == 0] = np.nan
        np.save(folder / f"depth{index}.npy", depth_m)
        np.save(folder / f"rgb{index}.npy", rgb)
        captures.append(entry)
    (folder / "calib.json").write_text(json.dumps(_calibration()))
    document = {"format": "fieldapp-session/1", "id": "hand-1", "calibration": "calib.json"}
    document["captures"] = captures
    (folder / "session.json").write_text(json.dumps(document))
    return folder
