"""The benchmark's Open3D reference measures plants as it says: fragments dropped, each plant's
height from its own ground, positions on the map."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType, SimpleNamespace

import numpy as np
import open3d as o3d
import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture(scope="module")
def reference() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "reference_pipeline", BENCHMARKS / "reference_pipeline.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("reference_pipeline", module)
    spec.loader.exec_module(module)
    return module


def _plant(x: float, y: float, ground_m: float, height_m: float, span_m: float) -> np.ndarray:
    """A seedling of 4 mm samples: a stem, and two leaves crossing at mid-height."""
    stem = np.arange(ground_m + 0.012, ground_m + height_m, 0.004)
    along = np.arange(-span_m / 2, span_m / 2 + 1e-9, 0.004)
    middle = np.full_like(along, ground_m + height_m / 2)
    zeros = np.zeros_like(along)
    return np.concatenate(
        [
            np.stack([np.full_like(stem, x), np.full_like(stem, y), stem], axis=1),
            np.stack([x + along, y + zeros, middle], axis=1),
            np.stack([x + zeros, y + along, middle], axis=1),
        ]
    )


def _soil(x: float, y: float, ground_m: float) -> np.ndarray:
    """1 cm soil samples on a square 1.2 m wide about (x, y) at height ``ground_m``."""
    side = np.arange(-0.6, 0.6, 0.01)
    gx, gy = np.meshgrid(x + side, y + side)
    return np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, ground_m)], axis=1)


def _cloud(points: np.ndarray) -> o3d.geometry.PointCloud:
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))


def test_plants_are_the_large_clusters_measured_from_their_own_ground(
    reference: ModuleType,
) -> None:
    # Two plants on soil 6 cm apart in height (an uneven plot), and a leaf fragment 30 cm
    # from either: too small to be a plant.
    first, second = _plant(0.0, 0.0, 0.03, 0.30, 0.40), _plant(0.8, 0.0, -0.03, 0.20, 0.30)
    fragment = _plant(0.4, 0.5, 0.0, 0.02, 0.02)
    plants = _cloud(np.concatenate([first, second, fragment]))
    soil = _cloud(np.concatenate([_soil(0.0, 0.0, 0.03), _soil(0.8, 0.0, -0.03)]))
    rows = sorted(reference.plant_traits(plants, soil), key=lambda row: row["x_m"])
    assert [row["points"] for row in rows] == [len(first), len(second)]
    assert [row["x_m"] for row in rows] == pytest.approx([0.0, 0.8], abs=0.005)
    assert [row["y_m"] for row in rows] == pytest.approx([0.0, 0.0], abs=0.005)
    assert [row["height_cm"] for row in rows] == pytest.approx([30.0, 20.0], abs=0.6)
    assert [row["width_cm"] for row in rows] == pytest.approx([40.0, 30.0], abs=0.6)


def test_positions_go_onto_the_map_by_the_reference_stations_base_pose(
    reference: ModuleType,
) -> None:
    def capture(station: int, x: float, y: float, yaw_deg: float) -> SimpleNamespace:
        return SimpleNamespace(
            station=station, base_pose=SimpleNamespace(x=x, y=y, yaw_deg=yaw_deg)
        )

    session = SimpleNamespace(
        captures=[capture(5, 1.6, 1.7, 89.0), capture(5, 1.6, 1.5, 91.0), capture(4, 0.0, 0.0, 0)]
    )
    T = reference.T_map_field(session, 5)
    assert T[:3, :3] @ [1.0, 0.0, 0.0] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    assert T[:3, 3] == pytest.approx([1.6, 1.6, 0.0])
    no_poses = SimpleNamespace(captures=[SimpleNamespace(station=5, base_pose=None)])
    assert np.array_equal(reference.T_map_field(no_poses, 5), np.eye(4))
