"""Registration cost against the number of overlapping pairs, on synthetic G x G plots or on
simulated capture sessions.

    .venv/bin/python benchmarks/bench_register.py [--grids 3,5,7,9] [--seed N] [--threads N]
    .venv/bin/python benchmarks/bench_register.py --session DIR [--session DIR ...]

Each station sees a bumpy soil with stems within 2.2 m of its axis (4 cm sampling), stations
1.6 m apart, arrival errors of 3 cm / 1.5 degrees. Prints per grid: stations, overlapping
pairs, CPU seconds of the pairwise registrations and of the graph (solve and guards), CPU per
pair, and the worst station's error against the truth. CPU figures are what to compare on a
shared machine; the pose graph should stay a small share and the total linear in the pairs.

With ``--session`` (a folder written by ``fieldapp simulate``, with its ``truth.json``) the
reconstruction runs up to registration once, then registration alone runs with 1 and with 2
threads (``--threads-list``): CPU and wall seconds of each, whether both placed every station
identically (they must), and the stations' median and worst error against the truth. The load
average is printed with each line: wall times on a loaded machine say little.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from devices.geometry import invert, make_transform, pose_error, rotation_z, transform_points
from fieldapp.io.session import load_session
from fieldapp.recon import register, stages
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.settings import ReconstructionSettings, RegistrationSettings

SPACING_M = 1.6
VIEW_RADIUS_M = 2.2


def synthetic_plot(
    seed: int, grid: int
) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], dict[int, np.ndarray], int]:
    """(points per station in its frame, coarse poses, true poses, reference station)."""
    rng = np.random.default_rng(seed)
    half = (grid - 1) * SPACING_M / 2 + VIEW_RADIUS_M
    xy = rng.uniform(-half, half, (int((2 * half) ** 2 * 700), 2))
    z = 0.015 * np.sin(2.1 * xy[:, 0] + 0.4) * np.cos(1.7 * xy[:, 1])
    z += 0.004 * np.sin(9 * xy[:, 0] - 7 * xy[:, 1])
    stems = []
    for x, y in rng.uniform(-half + 0.3, half - 0.3, (grid * grid, 2)):
        angle, height = rng.uniform(0, 2 * np.pi, 600), rng.uniform(0, 0.25, 600)
        stems.append(np.column_stack([x + 0.01 * np.cos(angle), y + 0.01 * np.sin(angle), height]))
    world = np.concatenate([np.column_stack([xy, z]), *stems])
    points, coarse, truth = {}, {}, {}
    offset = (grid - 1) * SPACING_M / 2
    for station in range(1, grid * grid + 1):
        row, col = divmod(station - 1, grid)
        nominal = np.array([col * SPACING_M - offset, row * SPACING_M - offset, 0.0])
        coarse[station] = make_transform(np.eye(3), nominal)
        error = make_transform(rotation_z(rng.normal(0, 1.5)), np.r_[rng.normal(0, 0.03, 2), 0])
        truth[station] = coarse[station] @ error
        seen = world[np.hypot(*(world[:, :2] - nominal[:2]).T) < VIEW_RADIUS_M]
        points[station] = transform_points(invert(truth[station]), seen)
    return points, coarse, truth, (grid * grid + 1) // 2


def measure(grid: int, seed: int, threads: int) -> None:
    points, coarse, truth, reference = synthetic_plot(seed, grid)
    settings = RegistrationSettings()
    pairs = 0
    solve_cpu = [0.0]
    original = register._solve_plot

    def timed_solve(*args, **kwargs):  # type: ignore[no-untyped-def]
        start = time.process_time()
        try:
            return original(*args, **kwargs)
        finally:
            solve_cpu[0] = time.process_time() - start

    register._solve_plot = timed_solve
    start = time.process_time()
    steps = register.register_stations(points, coarse, np.zeros(3), reference, settings, threads)
    while True:
        try:
            next(steps)
            pairs += 1
        except StopIteration as done:
            result = done.value
            break
    total = time.process_time() - start
    register._solve_plot = original
    T_ref = result[reference].T_field_station
    errors = [
        pose_error(invert(T_ref) @ r.T_field_station, invert(truth[reference]) @ truth[s])
        for s, r in result.items()
    ]
    pair_cpu = total - solve_cpu[0]
    print(
        f"{grid} x {grid}: {grid * grid} stations, {pairs} pairs, pairs {pair_cpu:.1f} s CPU "
        f"({1000 * pair_cpu / max(pairs, 1):.0f} ms per pair), graph and guards "
        f"{solve_cpu[0]:.2f} s, worst station {1000 * max(e[0] for e in errors):.1f} mm / "
        f"{max(e[1] for e in errors):.3f} deg, verdicts "
        f"{sorted({r.verdict for r in result.values()})}"
    )


class _Inputs(Exception):
    """Carries registration's arguments out of the pipeline, which stops there."""

    def __init__(self, arguments: tuple[Any, ...]) -> None:
        super().__init__("registration reached")
        self.arguments = arguments


def registration_inputs(folder: Path) -> tuple[Any, ...]:
    """The arguments ``fieldapp reconstruct`` gives registration for the session ``folder``."""

    def capture(*arguments: Any) -> Any:
        raise _Inputs(arguments)
        yield  # a generator, as register_stations

    real = stages.register_stations
    stages.register_stations = capture  # type: ignore[assignment]
    try:
        run_reconstruction(load_session(folder), ReconstructionSettings())
    except _Inputs as reached:
        return reached.arguments
    finally:
        stages.register_stations = real
    raise RuntimeError(f"{folder}: the reconstruction stopped before registration")


def measure_session(folder: Path, thread_counts: list[int]) -> None:
    points, coarse, axis, reference, settings, _ = registration_inputs(folder)
    truth = json.loads((folder / "truth.json").read_text())
    T_true = {int(s): np.array(m) for s, m in truth["T_field_camera"].items()}
    placed = []
    for threads in thread_counts:
        cpu, wall = time.process_time(), time.perf_counter()
        steps = register.register_stations(points, coarse, axis, reference, settings, threads)
        while True:
            try:
                next(steps)
            except StopIteration as done:
                result = done.value
                break
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        T_ref = result[reference].T_field_station
        errors = [
            pose_error(invert(T_ref) @ r.T_field_station, invert(T_true[reference]) @ T_true[s])
            for s, r in result.items()
        ]
        placed.append(np.stack([r.T_field_station for r in result.values()]))
        millimetres = [1000 * e[0] for e in errors]
        degrees = [e[1] for e in errors]
        print(
            f"{folder.name}: {len(result)} stations, threads {threads}: {cpu:.2f} s CPU, "
            f"{wall:.2f} s wall (load {os.getloadavg()[0]:.1f}); stations median "
            f"{np.median(millimetres):.2f} mm / {np.median(degrees):.3f} deg, worst "
            f"{max(millimetres):.2f} mm / {max(degrees):.3f} deg, "
            f"identical to the first: {np.array_equal(placed[0], placed[-1])}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grids", default="3,5,7,9")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--session", type=Path, action="append", default=[])
    parser.add_argument("--threads-list", default="1,2")
    args = parser.parse_args()
    if args.session:
        for folder in args.session:
            measure_session(folder, [int(t) for t in args.threads_list.split(",")])
        return
    for grid in (int(g) for g in args.grids.split(",")):
        measure(grid, args.seed, args.threads)


if __name__ == "__main__":
    main()
