"""The PLY module's speed: writing and reading a reconstruction-sized cloud, binary and ASCII,
against Open3D's reader on the same files.

    .venv/bin/python benchmarks/bench_ply.py [--points N] [--seeds 0 1 2]

Each seed draws ``--points`` points (float x, y, z, uchar RGB, int plant_id), writes them with
:func:`fieldapp.io.ply.write_ply`, reads them back, and reads an ASCII copy (x, y, z written by
Open3D); Open3D reads both files too. Wall-clock seconds, best of the seeds; a loaded machine
slows all of them.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import open3d as o3d

from fieldapp.io import ply

VERTEX = np.dtype(
    [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("red", "u1"),
        ("green", "u1"),
        ("blue", "u1"),
        ("plant_id", "<i4"),
    ]
)


def timed(work: Callable[[], object]) -> float:
    start = time.perf_counter()
    work()
    return time.perf_counter() - start


def run(points: int, seed: int, folder: Path) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    vertices = np.empty(points, VERTEX)
    for name in "xyz":
        vertices[name] = rng.normal(size=points)
    for name in ("red", "green", "blue"):
        vertices[name] = rng.integers(0, 256, points)
    vertices["plant_id"] = rng.integers(0, 100, points)
    binary, ascii = folder / "binary.ply", folder / "ascii.ply"
    cloud = o3d.geometry.PointCloud()
    cloud.points = o3d.utility.Vector3dVector(ply.points_of(vertices))
    o3d.io.write_point_cloud(str(ascii), cloud, write_ascii=True)
    return {
        "binary write": timed(lambda: ply.write_ply(binary, vertices)),
        "binary read": timed(lambda: ply.read_ply(binary)),
        "binary read (Open3D)": timed(lambda: o3d.io.read_point_cloud(str(binary))),
        "ascii read": timed(lambda: ply.read_ply(ascii)),
        "ascii read (Open3D)": timed(lambda: o3d.io.read_point_cloud(str(ascii))),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        runs = [run(args.points, seed, Path(folder)) for seed in args.seeds]
    for key in runs[0]:
        print(f"{key:22s} {min(r[key] for r in runs):.3f} s  (seeds {args.seeds})")


if __name__ == "__main__":
    main()
