"""Simulation speed: a 72-frame session (9 stations x 8 views) written by ``fieldapp simulate``.

    .venv/bin/python benchmarks/bench_simulate.py [--repeats N] [--scene plot]

Prints the wall time of whole sessions (target: under 20 s on the project's 2-core machine),
then a breakdown: world building, one frame's render, one capture's encoding and durable
writing. Figures depend on the machine's load: rerun when it is quiet (``uptime``).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from devices.sim.rig import RigGeometry
from devices.sim.scene import plot_scene
from devices.sim.world import SimWorld
from fieldapp.cli import main as fieldapp_main


def cpu_s() -> float:
    """User + system CPU time of this process (all its threads) so far."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def time_sessions(scene: str, repeats: int) -> list[float]:
    times = []
    for index in range(repeats):
        with tempfile.TemporaryDirectory() as folder:
            start, start_cpu = time.perf_counter(), cpu_s()
            code = fieldapp_main(
                ["simulate", "--out", f"{folder}/s", "--scene", scene, "--seed", str(index)]
            )
            times.append(time.perf_counter() - start)
            cpu = cpu_s() - start_cpu
            if code != 0:
                raise SystemExit(f"fieldapp simulate failed with exit code {code}")
            frames = len(list(Path(folder, "s", "frames").rglob("depth.png")))
            size_mb = sum(p.stat().st_size for p in Path(folder, "s").rglob("*")) / 1e6
            print(
                f"  session {index}: {times[-1]:.2f} s wall, {cpu:.2f} s CPU, {frames} captures, "
                f"{size_mb:.0f} MB"
            )
    return times


def breakdown() -> None:
    start = time.perf_counter()
    scene = plot_scene(0)
    world = SimWorld(scene, RigGeometry())
    print(f"  build the plot scene: {time.perf_counter() - start:.2f} s")
    world.render(np.random.default_rng(0))  # builds the BVH
    renders = []
    for view in range(16):
        world.set_table_angle_deg(22.5 * view)
        start = time.perf_counter()
        frame = world.render(np.random.default_rng(view))
        renders.append(time.perf_counter() - start)
    print(f"  render one frame: median {1000 * statistics.median(renders):.0f} ms")
    from fieldapp.io.images import depth_m_to_units, encode_png

    start = time.perf_counter()
    for _ in range(5):
        encode_png(depth_m_to_units(frame.depth_m, 1000.0))
        encode_png(frame.color, rgb=True)
        assert frame.ir is not None
        encode_png(frame.ir)
    print(f"  encode one capture's three PNGs: {1000 * (time.perf_counter() - start) / 5:.0f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scene", default="plot")
    args = parser.parse_args()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    print(f"72-frame {args.scene} sessions:")
    times = time_sessions(args.scene, args.repeats)
    print(f"  median {statistics.median(times):.2f} s, best {min(times):.2f} s (target < 20 s)")
    print("breakdown:")
    breakdown()


if __name__ == "__main__":
    main()
