"""Batch speed: N sessions one by one, then as a batch on a local Dask cluster.

    .venv/bin/python benchmarks/bench_batch.py [--sessions 12] [--workers 2]
        [--stations 4,5] [--views 0-7] [--keep DIR] [--in-process]

Simulates N plot sessions (seeds 0..N-1) into a temporary folder (or ``--keep DIR``, reused
when it already holds them), then:

- one by one: ``fieldapp reconstruct`` of each session in turn, each in its own process as a
  user runs them (start-up included), with the default settings (two reconstruction
  threads); with ``--in-process``, ``run_reconstruction`` + ``write_outputs`` for each
  session in this process instead (no start-up per session: the harder comparison);
- batch: what ``fieldapp batch`` does (plan, local cluster of ``--workers`` single-threaded
  workers, one task per session, runs recorded in a fresh results database), cluster start-up
  and shutdown included.

Prints wall and CPU time of both (the batch's CPU includes its worker processes), the
workers' peak memory, the load average around each run (the machine may be shared: rerun when
it is quiet), and how the plants.csv files agree. The one-by-one run uses two threads, the
batch one per task; both give the same files (every pair and plant runs on one OpenMP thread
wherever it runs, ``fieldapp/recon/forkmap.py``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import resource
import shutil
import tempfile
import time
from pathlib import Path


def simulate(root: Path, count: int, stations: str, views: str) -> list[Path]:
    from fieldapp.cli import main

    folders = []
    for seed in range(count):
        folder = root / f"s{seed:03d}"
        if not (folder / "session.json").is_file():
            argv = ["simulate", "--out", str(folder), "--seed", str(seed)]
            with contextlib.redirect_stdout(io.StringIO()):
                main([*argv, "--stations", stations, "--views", views])
        folders.append(folder)
    return folders


def one_by_one_cli(folders: list[Path], out: Path) -> tuple[float, float, float]:
    """``fieldapp reconstruct`` of each session in turn, each its own process as a user runs
    it (start-up included, default settings: two threads): (wall s, CPU s, peak MB)."""
    import subprocess
    import sys

    from fieldapp.io.session import load_session

    fieldapp = Path(sys.executable).with_name("fieldapp")
    start, cpu, peak = time.perf_counter(), 0.0, 0.0
    for folder in folders:
        target = out / load_session(folder).id
        argv = [str(fieldapp), "reconstruct", str(folder), "--out", str(target)]
        process = subprocess.Popen([*argv, "--quiet"], stdout=subprocess.DEVNULL)
        _, status, usage = os.wait4(process.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError(f"{' '.join(argv)} failed")
        cpu += usage.ru_utime + usage.ru_stime
        peak = max(peak, usage.ru_maxrss / 1024.0)
    return time.perf_counter() - start, cpu, peak


def one_by_one(folders: list[Path], out: Path) -> tuple[float, float]:
    from fieldapp.io.session import load_session
    from fieldapp.recon.outputs import write_outputs
    from fieldapp.recon.pipeline import run_reconstruction
    from fieldapp.recon.settings import ReconstructionSettings

    start, start_cpu = time.perf_counter(), time.process_time()
    for folder in folders:
        session = load_session(folder)
        result = run_reconstruction(session, ReconstructionSettings())
        plant_clouds = {p.id: p.cloud for p in result.plants}
        target = out / session.id
        write_outputs(target, result.rows(), result.cloud, plant_clouds, result.report())
    return time.perf_counter() - start, time.process_time() - start_cpu


def batch(folders: list[Path], out: Path, workers: int) -> tuple[float, float, float, float, int]:
    """(wall s, CPU s of this process, CPU s of its workers, workers' peak MB, sessions
    done)."""
    from fieldapp import __version__
    from fieldapp.batch.cluster import open_client
    from fieldapp.batch.plan import plan_batch, task_settings
    from fieldapp.batch.runner import run_batch
    from fieldapp.recon.settings import ReconstructionSettings
    from fieldapp.results.db import ResultsDB

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start, start_cpu = time.perf_counter(), time.process_time()
    with ResultsDB.open(out / "results.sqlite") as db:
        settings = task_settings(ReconstructionSettings())
        plan = plan_batch(folders, settings, __version__, db, out)
        with open_client(None, workers, "auto") as client:
            outcomes = run_batch(client, plan, out, db)
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    children_cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    done = sum(o.status == "done" for o in outcomes)
    return wall, cpu, children_cpu, after.ru_maxrss / 1024.0, done


def compare(first: Path, second: Path) -> str:
    """How the plants.csv files of the two runs agree: how many are byte for byte the same,
    and the largest difference of each column over the others."""
    import numpy as np

    names = sorted(p.relative_to(first) for p in first.glob("*/plants.csv"))
    same, largest = 0, np.zeros(6)
    for name in names:
        a, b = (first / name).read_bytes(), (second / name).read_bytes()
        if a == b:
            same += 1
            continue
        rows_a, rows_b = (np.loadtxt(io.BytesIO(t), delimiter=",", skiprows=1) for t in (a, b))
        if rows_a.shape != rows_b.shape:
            return f"{name}: {len(rows_a)} plants against {len(rows_b)}"
        largest = np.maximum(largest, np.abs(rows_a - rows_b).reshape(-1, 6).max(axis=0))
    if same == len(names):
        return f"{same}/{len(names)} byte for byte"
    names_ = ["x_m", "y_m", "height_cm", "width_cm", "points"]
    columns = ", ".join(f"{c} {d:g}" for c, d in zip(names_, largest[1:], strict=True))
    return f"{same}/{len(names)} byte for byte; the others differ by at most: {columns}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=12)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--stations", default="4,5")
    parser.add_argument("--views", default="0-7")
    parser.add_argument("--keep", type=Path, help="simulate into (and reuse) this folder")
    parser.add_argument(
        "--in-process",
        action="store_true",
        help="one by one in this process (no start-up per session), not fieldapp reconstruct",
    )
    args = parser.parse_args()
    import logging

    logging.basicConfig(level=logging.ERROR)
    with tempfile.TemporaryDirectory() as temporary:
        root = args.keep or Path(temporary)
        outputs = root / "outputs"
        for old in ("one-by-one", "batch"):
            shutil.rmtree(outputs / old, ignore_errors=True)
        folders = simulate(root / "sessions", args.sessions, args.stations, args.views)
        print(f"{len(folders)} sessions: stations {args.stations}, views {args.views}")
        print(f"load average before: {os.getloadavg()[0]:.2f}")
        if args.in_process:
            serial_s, serial_cpu_s = one_by_one(folders, outputs / "one-by-one")
            print(f"one by one in this process: {serial_s:.1f} s wall, {serial_cpu_s:.1f} s CPU")
        else:
            serial_s, serial_cpu_s, serial_mb = one_by_one_cli(folders, outputs / "one-by-one")
            print(
                f"one by one (fieldapp reconstruct): {serial_s:.1f} s wall, {serial_cpu_s:.1f} s "
                f"CPU, peak {serial_mb:.0f} MB"
            )
        print(f"load average: {os.getloadavg()[0]:.2f}")
        wall_s, client_s, workers_s, peak_mb, done = batch(folders, outputs / "batch", args.workers)
        print(
            f"batch on {args.workers} workers: {wall_s:.1f} s wall, CPU {client_s:.1f} s client "
            f"+ {workers_s:.1f} s workers, {done} done, worker peak {peak_mb:.0f} MB"
        )
        print(f"load average after: {os.getloadavg()[0]:.2f}")
        print(f"speed-up: {serial_s / wall_s:.2f} x")
        print(f"plants.csv: {compare(outputs / 'one-by-one', outputs / 'batch')}")


if __name__ == "__main__":
    main()
