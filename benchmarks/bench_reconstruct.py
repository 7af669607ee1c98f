"""Reconstruction speed: fieldapp's pipeline beside a straightforward Open3D one, same session.

    .venv/bin/python benchmarks/bench_reconstruct.py [--session DIR] [--repeats N]

Without ``--session`` a standard 72-frame plot session is simulated into a temporary folder.
Each pipeline runs in its own process (so peak memory is its own): wall time, time per stage,
peak resident memory. fieldapp's run also prints its accuracy against ``truth.json`` when the
session has one. Figures depend on the machine's load: rerun when it is quiet.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np


def peak_memory_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_fieldapp(folder: Path) -> dict[str, Any]:
    from fieldapp.io.session import load_session
    from fieldapp.recon.pipeline import run_reconstruction
    from fieldapp.recon.settings import ReconstructionSettings

    start, start_cpu = time.perf_counter(), time.process_time()
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    poses = {s: result.T_reference_station(s) for s in result.registrations}
    return {
        "wall_s": wall,
        "cpu_s": cpu,
        "stages_s": result.timings_s,
        "stages_cpu_s": result.cpu_s,
        "plants": len(result.plants),
    } | station_errors(folder, result.reference, poses)


def run_open3d(folder: Path) -> dict[str, Any]:
    """The obvious Open3D pipeline: every frame to a cloud, views and stations joined by the
    calibration, voxel grid, RANSAC ground, ExG/Otsu, SOR + ROR, point-to-plane ICP of each
    station onto the reference station, DBSCAN."""
    import open3d as o3d

    from fieldapp.io.session import load_session
    from fieldapp.recon.filters import excess_green, otsu_threshold
    from fieldapp.recon.station import T_view0_view

    stages: dict[str, float] = {}
    stages_cpu: dict[str, float] = {}

    def timed(name: str, start: tuple[float, float]) -> tuple[float, float]:
        now = (time.perf_counter(), time.process_time())
        stages[name] = stages.get(name, 0.0) + now[0] - start[0]
        stages_cpu[name] = stages_cpu.get(name, 0.0) + now[1] - start[1]
        return now

    t0 = t = (time.perf_counter(), time.process_time())
    session = load_session(folder)
    calibration = session.calibration
    assert calibration.view_step is not None and calibration.stations is not None
    camera = calibration.depth_camera
    intrinsic = o3d.camera.PinholeCameraIntrinsic(
        camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy
    )
    stations: dict[int, o3d.geometry.PointCloud] = {}
    for capture in session.captures:
        depth = o3d.io.read_image(str(session.path_of(capture.depth)))
        color = o3d.io.read_image(str(session.path_of(capture.color)))
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            color,
            depth,
            depth_scale=camera.depth_scale,
            depth_trunc=2.25,
            convert_rgb_to_intensity=False,
        )
        cloud = o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, intrinsic)
        cloud.transform(T_view0_view(calibration.view_step.matrix, capture.view))
        stations.setdefault(capture.station, o3d.geometry.PointCloud())
        stations[capture.station] += cloud
    t = timed("load + back-project (legacy)", t)
    for station in stations:
        stations[station] = stations[station].voxel_down_sample(0.005)
        stations[station].transform(calibration.stations.to_reference[station])
    t = timed("voxel grid 5 mm", t)
    reference = calibration.stations.reference
    target = stations[reference]
    target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.05, max_nn=30))
    target = target.voxel_down_sample(0.02)
    T_reference_station = {reference: np.eye(4)}
    for station, cloud in stations.items():
        if station == reference:
            continue
        result = o3d.pipelines.registration.registration_icp(
            cloud.voxel_down_sample(0.02),
            target,
            0.1,
            np.eye(4),
            o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        )
        cloud.transform(result.transformation)
        T_reference_station[station] = (
            result.transformation @ calibration.stations.to_reference[station]
        )
    t = timed("ICP point-to-plane (2 cm) onto the reference", t)
    merged = o3d.geometry.PointCloud()
    for cloud in stations.values():
        merged += cloud
    _, ground = merged.segment_plane(0.01, 3, 1000)
    above = merged.select_by_index(ground, invert=True)
    t = timed("RANSAC ground", t)
    colors = (np.asarray(above.colors) * 255).astype(np.uint8)
    exg = excess_green(colors)
    plants = above.select_by_index(np.flatnonzero(exg > otsu_threshold(exg)).tolist())
    t = timed("ExG + Otsu", t)
    plants, _ = plants.remove_statistical_outlier(35, 1.5)
    plants, _ = plants.remove_radius_outlier(5, 0.008)
    t = timed("SOR + ROR (legacy)", t)
    labels = np.asarray(plants.cluster_dbscan(0.02, 10))
    t = timed("DBSCAN", t)
    return {
        "wall_s": t[0] - t0[0],
        "cpu_s": t[1] - t0[1],
        "stages_s": stages,
        "stages_cpu_s": stages_cpu,
        "plants": int(labels.max() + 1),
    } | station_errors(folder, reference, T_reference_station)


def station_errors(
    folder: Path, reference: int, T_reference_station: dict[int, Any]
) -> dict[str, float]:
    """Worst station pose error (relative to the reference) against ``truth.json``, if any."""
    from devices.geometry import invert, pose_error

    truth_file = folder / "truth.json"
    if not truth_file.exists():
        return {}
    truth = json.loads(truth_file.read_text())
    T = {int(s): np.array(m) for s, m in truth["T_field_camera"].items()}
    errors = [
        pose_error(T_est, invert(T[reference]) @ T[s]) for s, T_est in T_reference_station.items()
    ]
    return {
        "max_station_error_mm": max(e[0] for e in errors) * 1000,
        "max_station_error_deg": max(e[1] for e in errors),
    }


def child(kind: str, folder: Path) -> None:
    figures = run_fieldapp(folder) if kind == "fieldapp" else run_open3d(folder)
    figures["peak_memory_mb"] = peak_memory_mb()
    print(json.dumps(figures))


def in_process(kind: str, folder: Path) -> dict[str, Any]:
    output = subprocess.run(
        [sys.executable, __file__, "--child", kind, "--session", str(folder)],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(output.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def simulate(folder: Path) -> Path:
    session = folder / "plot"
    subprocess.run(
        [str(Path(sys.executable).parent / "fieldapp"), "simulate", "--out", str(session)],
        check=True,
        capture_output=True,
    )
    return session


def report(kind: str, runs: list[dict[str, Any]]) -> None:
    walls = [r["wall_s"] for r in runs]
    print(
        f"\n== {kind}: wall median {statistics.median(walls):.2f} s "
        f"(runs: {', '.join(f'{w:.2f}' for w in walls)}), "
        f"CPU median {statistics.median(r['cpu_s'] for r in runs):.2f} s, "
        f"peak memory {max(r['peak_memory_mb'] for r in runs):.0f} MB, "
        f"plants {runs[-1]['plants']}"
    )
    print(f"   {'stage':46s} {'wall s':>8s} {'CPU s':>8s}")
    for stage in runs[0]["stages_s"]:
        wall = statistics.median(r["stages_s"][stage] for r in runs)
        cpu = statistics.median(r["stages_cpu_s"][stage] for r in runs)
        print(f"   {stage:46s} {wall:8.3f} {cpu:8.3f}")
    for key in ("max_station_error_mm", "max_station_error_deg"):
        if key in runs[-1]:
            print(f"   {key:46s} {runs[-1][key]:8.3f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--session", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--child", choices=["fieldapp", "open3d"])
    args = parser.parse_args()
    if args.child:
        child(args.child, args.session)
        return 0
    with tempfile.TemporaryDirectory() as scratch:
        folder = args.session or simulate(Path(scratch))
        frames = len(json.loads((folder / "session.json").read_text())["captures"])
        with open("/proc/loadavg") as load:
            print(f"session {folder}: {frames} frames; load average {load.read().split()[:3]}")
        ours = [in_process("fieldapp", folder) for _ in range(args.repeats)]
        reference = [in_process("open3d", folder)]
        report("fieldapp", ours)
        report("straightforward Open3D", reference)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
