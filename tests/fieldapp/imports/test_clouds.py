"""``fieldapp import cloud``: point clouds of other tools straight to plants and traits."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from fieldapp.cli import main
from fieldapp.errors import FieldappError
from fieldapp.imports.cloud_traits import cloud_traits
from fieldapp.imports.clouds import read_cloud, up_rotation
from fieldapp.settings import Settings

PLANTS = [((-0.3, 0.0), 0.25, 0.04), ((0.3, 0.1), 0.15, 0.06), ((0.0, -0.35), 0.35, 0.05)]
"""(x, y) of the base, height and radius (m) of each synthetic plant."""


def _plant(x: float, y: float, height: float, radius: float) -> np.ndarray:
    """A stem (4 mm radius) ``height`` tall with a flat disc of leaves of ``radius`` halfway up."""
    turn, z = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.arange(0.0, height, 0.002))
    stem = np.column_stack(
        [x + 0.004 * np.cos(turn.ravel()), y + 0.004 * np.sin(turn.ravel()), z.ravel()]
    )
    u, v = np.meshgrid(np.arange(-radius, radius, 0.002), np.arange(-radius, radius, 0.002))
    inside = (u**2 + v**2 <= radius**2) & (u**2 + v**2 >= 0.006**2)
    disc = np.column_stack([x + u[inside], y + v[inside], np.full(inside.sum(), height / 2)])
    return np.concatenate([stem, disc])


def synthetic_plot(seed: int, tilt_deg: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """A 1.2 m square of brown soil (1 mm noise) with green cylinders standing on it, tilted
    ``tilt_deg`` about x and lifted 0.4 m (the file's frame is not the field frame)."""
    rng = np.random.default_rng(seed)
    gx, gy = np.meshgrid(np.arange(-0.6, 0.6, 0.006), np.arange(-0.6, 0.6, 0.006))
    soil = np.column_stack([gx.ravel(), gy.ravel(), rng.normal(0, 0.001, gx.size)])
    parts, colors = [soil], [np.tile([120, 90, 60], (len(soil), 1))]
    for (x, y), height, radius in PLANTS:
        parts.append(_plant(x, y, height, radius) + rng.normal(0, 0.0005, (1, 3)))
        colors.append(np.tile([40, 150, 40], (len(parts[-1]), 1)))
    return to_file(np.concatenate(parts), tilt_deg), np.concatenate(colors).astype(np.uint8)


def write_ply(path: Path, points: np.ndarray, colors: np.ndarray | None) -> Path:
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if colors is not None:
        cloud.colors = o3d.utility.Vector3dVector(colors / 255.0)
    assert o3d.io.write_point_cloud(str(path), cloud)
    return path


def write_las(path: Path, points: np.ndarray, colors: np.ndarray) -> Path:
    import laspy

    header = laspy.LasHeader(point_format=2, version="1.2")
    header.scales, header.offsets = [0.0001] * 3, points.min(axis=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points.T
    las.red, las.green, las.blue = (colors.astype(np.uint16) * 257).T
    las.write(path)
    return path


def _plants(folder: Path) -> list[dict[str, str]]:
    with (folder / "plants.csv").open() as handle:
        return list(csv.DictReader(handle))


def _check(rows: list[dict[str, str]], T_field_file: np.ndarray, file_from_plot) -> None:
    """Each plant found where its base lands through the levelling, its height (the top of the
    stem) within 6 mm and its width (the disc's diameter) within 8 mm: the outlier filters trim
    the rim of a flat sheet by about 3 mm (0.55-0.6 cm on the diameter over seeds 0-2)."""
    assert len(rows) == len(PLANTS)
    for (x, y), height, radius in PLANTS:
        base = file_from_plot(np.array([[x, y, 0.0]]))
        x_m, y_m, _ = (T_field_file[:3, :3] @ base[0]) + T_field_file[:3, 3]
        row = min(rows, key=lambda r: np.hypot(float(r["x_m"]) - x_m, float(r["y_m"]) - y_m))
        assert np.hypot(float(row["x_m"]) - x_m, float(row["y_m"]) - y_m) < 0.01
        top_m = np.arange(0.0, height, 0.002).max()
        assert float(row["height_cm"]) == pytest.approx(100 * top_m, abs=0.6)
        assert float(row["width_cm"]) == pytest.approx(200 * radius, abs=0.8)


def to_file(points: np.ndarray, tilt_deg: float = 3.0) -> np.ndarray:
    """The synthetic plot's coordinates into the file's: tilted about x, lifted 0.4 m."""
    c, s = np.cos(np.radians(tilt_deg)), np.sin(np.radians(tilt_deg))
    return points @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T + [0.0, 0.0, 0.4]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ply_with_colour_gives_every_plant_and_its_traits(tmp_path, seed, capsys):
    points, colors = synthetic_plot(seed)
    path = write_ply(tmp_path / "plot.ply", points, colors)
    out = tmp_path / "results"
    assert main(["import", "cloud", str(path), "--out", str(out)]) == 0
    assert "ground plane by RANSAC" in capsys.readouterr().out
    report = json.loads((out / "report.json").read_text())
    _check(_plants(out), np.array(report["T_field_file"]), to_file)
    assert report["plant_separation"].startswith("green")
    assert sorted(p.name for p in (out / "plants").glob("*.ply")) == ["1.ply", "2.ply", "3.ply"]


def test_laz_in_millimetres_with_y_up(tmp_path, capsys):
    points, colors = synthetic_plot(3)
    y_up = points[:, [0, 2, 1]] * [1, 1, -1] * 1000.0  # x, z, -y: y is up, millimetres
    path = write_las(tmp_path / "plot.laz", y_up, colors)
    out = tmp_path / "results"
    args = ["import", "cloud", str(path), "--units", "mm", "--up", "y"]
    assert main([*args, "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    _check(_plants(out), np.array(report["T_field_file"]), to_file)


def test_xyz_without_colour_is_separated_by_geometry(tmp_path):
    points, _ = synthetic_plot(4)
    path = tmp_path / "plot.xyz"
    np.savetxt(path, points, fmt="%.5f")
    loaded = read_cloud(path)
    assert not loaded.has_color
    result = cloud_traits(loaded, Settings().reconstruction, 0.02)
    assert result.separation.startswith("geometry only (no colour)")
    assert len(result.plants) == len(PLANTS)


def test_pcd_of_a_plant_without_ground_uses_its_lowest_points(tmp_path):
    points, colors = synthetic_plot(5, tilt_deg=0.0)
    last = len(_plant(0.0, 0.0, PLANTS[-1][1], PLANTS[-1][2]))
    plant = points[-last:]  # the last plant alone: no soil around it
    path = write_ply(tmp_path / "plant.pcd", plant, colors[-last:])
    result = cloud_traits(read_cloud(path), Settings().reconstruction, 0.02)
    assert result.ground.startswith("no ground plane")
    assert len(result.plants) == 1


def test_up_rotations_are_rotations_taking_up_to_z():
    for up in ("z", "-z", "y", "-y", "x", "-x"):
        R = up_rotation(up)
        axis = {"x": 0, "y": 1, "z": 2}[up[-1]]
        vector = np.zeros(3)
        vector[axis] = -1.0 if up.startswith("-") else 1.0
        np.testing.assert_allclose(R @ vector, [0, 0, 1])
        assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("plot.obj", b"v 0 0 0\n", "not a point cloud fieldapp reads"),
        ("plot.ply", b"garbage", "no point read"),
        ("plot.las", b"garbage", "not a readable LAS/LAZ file"),
    ],
)
def test_unreadable_clouds_are_named(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(FieldappError, match=message):
        read_cloud(path)
    with pytest.raises(FieldappError, match="--units 'ft'"):
        read_cloud(path, units="ft")
