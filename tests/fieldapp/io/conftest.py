"""A session folder written the way another tool following the spec would write it."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from devices.geometry import make_transform, rotation_y, rotation_z

WIDTH, HEIGHT = 64, 48


def rigid(angle_deg: float, t: tuple[float, float, float]) -> list[list[float]]:
    return make_transform(rotation_y(angle_deg), np.array(t)).tolist()


def calibration_document() -> dict[str, Any]:
    return {
        "format": "fieldapp-calibration/1",
        "depth_camera": {
            "width": WIDTH,
            "height": HEIGHT,
            "fx": 60.0,
            "fy": 60.5,
            "cx": 32.0,
            "cy": 24.0,
            "distortion": [0, 0, 0, 0, 0],
            "depth_scale": 1000.0,
        },
        "view_step": {"angle_deg": 90.0, "matrix": rigid(90.0, (0.1, 0.0, 0.1))},
        "stations": {
            "reference": 2,
            "to_reference": {"1": rigid(0.0, (-1.6, 0, 0)), "2": rigid(0.0, (0, 0, 0))},
        },
        "ground": {"matrix": make_transform(rotation_z(10.0), np.array([0, 0, 1.3])).tolist()},
        "vendor_note": "fields a reader does not know are ignored",
    }


def depth_image(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    depth = rng.integers(500, 4500, size=(HEIGHT, WIDTH), dtype=np.uint16)
    depth[:3, :5] = 0  # no measurement
    return depth


def color_image(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed + 1000)
    return rng.integers(0, 256, size=(HEIGHT, WIDTH, 3), dtype=np.uint8)


SessionFactory = Callable[..., Path]


@pytest.fixture
def make_spec_session(tmp_path: Path) -> SessionFactory:
    """Write a session by hand (json + cv2), like a third-party recorder; returns its folder.

    ``stations`` x ``views`` captures; ``skip`` leaves (station, view) pairs out.
    """

    def make(
        stations: tuple[int, ...] = (1, 2),
        views: int = 4,
        skip: tuple[tuple[int, int], ...] = (),
        name: str = "session",
    ) -> Path:
        folder = tmp_path / name
        frames = folder / "data"
        frames.mkdir(parents=True)
        (folder / "calibration.json").write_text(json.dumps(calibration_document(), indent=1))
        captures = []
        for station in stations:
            for view in range(views):
                if (station, view) in skip:
                    continue
                seed = station * 100 + view
                depth_name = f"data/st{station}_v{view}_d.png"
                color_name = (
                    f"data/st{station}_v{view}_c.jpg"
                    if view == 1
                    else (f"data/st{station}_v{view}_c.png")
                )
                cv2.imwrite(str(folder / depth_name), depth_image(seed))
                cv2.imwrite(str(folder / color_name), color_image(seed)[:, :, ::-1])
                captures.append(
                    {
                        "station": station,
                        "view": view,
                        "angle_deg": 90.0 * view + 0.01,
                        "depth": depth_name,
                        "color": color_name,
                        "captured_at": "2022-06-07T09:31:02+08:00",
                        "base_pose": {"x": 0.02, "y": -0.01, "yaw_deg": 0.4},
                        "exposure_us": 1200,
                    }
                )
        document = {
            "format": "fieldapp-session/1",
            "id": "2022-06-07-plot-a",
            "created": "2022-06-07T09:30:00+08:00",
            "calibration": "calibration.json",
            "captures": captures,
            "operator": "another tool",
        }
        (folder / "session.json").write_text(json.dumps(document, indent=1))
        return folder

    return make


def _edit_json(path: Path, change: Callable[[Any], object]) -> None:
    document = json.loads(path.read_text())
    change(document)
    path.write_text(json.dumps(document))


@pytest.fixture
def edit_json() -> Callable[[Path, Callable[[Any], object]], None]:
    """``edit_json(path, change)``: load a JSON file, let ``change`` mutate it, write it back."""
    return _edit_json
