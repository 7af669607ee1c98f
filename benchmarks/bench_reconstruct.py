"""Reconstruction cost and accuracy: ``fieldapp reconstruct`` against an honest reference.

    .venv/bin/python benchmarks/bench_reconstruct.py [--session DIR ...] [--pairs N]

The reference is ``reference_pipeline.py``: the paper's method in the paper's order with plain
Open3D calls (filters before registration, ICP on the overlaps, DBSCAN), what a competent
engineer writes in an afternoon. Both run as a user runs them, each in its own process from
start-up to ``plants.csv`` on disk, in pairs (the order alternating from pair to pair) on the
same sessions, so a change in the machine's load hits both alike. Per run: wall time, CPU time
(user + system, every thread) and peak resident memory from the process's own rusage; per pair
the ratios reference / fieldapp; and each side's accuracy against ``truth.json`` (plants found,
phantoms, height and width RMSE and MAPE). Without ``--session`` two standard plot sessions are
simulated first. The load average is printed before and after: rerun when it is high.

As a user runs them means with Python's bytecode cached: the children run without
``PYTHONDONTWRITEBYTECODE`` (set in some shells and containers, where every start-up would
compile the modules again: 0.1-0.15 s for fieldapp's), and each side runs once on each session
before the measured pairs, unmeasured, which writes the caches and reads the session's files
into the page cache for both alike.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
FIELDAPP = Path(sys.executable).with_name("fieldapp")
MATCH_RADIUS_M = 0.12


CHILD_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def measured(argv: list[str]) -> dict[str, float]:
    """Run ``argv`` to the end; its wall, CPU (user + system) and peak memory."""
    start = time.perf_counter()
    process = subprocess.Popen(
        argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=CHILD_ENV
    )
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    process.returncode = os.waitstatus_to_exitcode(status)
    stderr = process.stderr.read().decode() if process.stderr else ""
    if process.returncode != 0:
        raise RuntimeError(f"{argv[:3]} failed ({process.returncode}): {stderr[-2000:]}")
    return {
        "wall_s": wall,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "peak_mb": usage.ru_maxrss / 1024.0,
    }


def accuracy(results: Path, session: Path) -> dict[str, float]:
    """Plants found and phantoms, height and width RMSE (cm) and MAPE (%) against the truth."""
    from fieldapp.evaluate.metrics import agreement
    from fieldapp.evaluate.references import load_truth, pair_with_truth
    from fieldapp.results.files import read_plants_csv

    truth = load_truth(session / "truth.json")
    pairing = pair_with_truth(read_plants_csv(results / "plants.csv"), truth.plants, MATCH_RADIUS_M)
    pairs = pairing.pairs
    height = agreement([p.height_cm for p in pairs], [p.reference_height_cm for p in pairs])
    width = agreement([p.width_cm for p in pairs], [p.reference_width_cm for p in pairs])
    return {
        "found": len(pairs),
        "truth": len(truth.plants),
        "phantoms": len(pairing.unmatched_plants),
        "height_rmse_cm": height.rmse or float("nan"),
        "height_mape": height.mape_percent or float("nan"),
        "width_rmse_cm": width.rmse or float("nan"),
        "width_mape": width.mape_percent or float("nan"),
    }


def run(kind: str, session: Path, scratch: Path, reference_voxel_m: float) -> dict[str, float]:
    out = Path(tempfile.mkdtemp(dir=scratch))
    if kind == "fieldapp":
        argv = [str(FIELDAPP), "reconstruct", str(session), "--out", str(out), "--quiet"]
    else:
        argv = [sys.executable, __file__, "--child", "--session", str(session), "--out", str(out)]
        argv += ["--reference-voxel", str(reference_voxel_m)]
    figures = measured(argv)
    if (session / "truth.json").exists():
        figures |= accuracy(out, session)
    return figures


def simulate(scratch: Path, seed: int) -> Path:
    folder = scratch / f"plot-seed{seed}"
    argv = [str(FIELDAPP), "simulate", "--out", str(folder), "--seed", str(seed)]
    subprocess.run(argv, check=True, capture_output=True)
    return folder


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def describe(name: str, f: dict[str, Any]) -> str:
    text = (
        f"{name:9s} wall {f['wall_s']:6.2f} s  CPU {f['cpu_s']:6.2f} s  peak {f['peak_mb']:5.0f} MB"
    )
    if "found" in f:
        text += (
            f"  plants {f['found']}/{f['truth']} +{f['phantoms']} phantom"
            f"  height {f['height_rmse_cm']:.2f} cm {f['height_mape']:.2f} %"
            f"  width {f['width_rmse_cm']:.2f} cm {f['width_mape']:.2f} %"
        )
    return text


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--session", type=Path, action="append", default=[])
    parser.add_argument("--pairs", type=int, default=3, help="paired runs per session")
    parser.add_argument(
        "--reference-voxel",
        type=float,
        default=0.002,
        help="the reference's plant voxel in metres (default 0.002, the paper's resolution; "
        "0.005 is the cheaper choice an engineer might make, at a cost in accuracy)",
    )
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        sys.path.insert(0, str(HERE))
        from reference_pipeline import reconstruct

        reconstruct(args.session[0], args.out, args.reference_voxel)
        return 0
    with tempfile.TemporaryDirectory() as scratch_name:
        scratch = Path(scratch_name)
        sessions = args.session or [simulate(scratch, seed) for seed in (1, 2)]
        print(f"load average before: {load()}  ({os.cpu_count()} CPUs)")
        ratios: dict[str, list[float]] = {"wall": [], "cpu": [], "memory": []}
        for session in sessions:
            print(f"\n== {session}")
            for kind in ("fieldapp", "reference"):  # unmeasured: caches written, files read
                run(kind, session, scratch, args.reference_voxel)
            for pair in range(args.pairs):
                order = ["fieldapp", "reference"] if pair % 2 == 0 else ["reference", "fieldapp"]
                figures = {
                    kind: run(kind, session, scratch, args.reference_voxel) for kind in order
                }
                ours, ref = figures["fieldapp"], figures["reference"]
                ratios["wall"].append(ref["wall_s"] / ours["wall_s"])
                ratios["cpu"].append(ref["cpu_s"] / ours["cpu_s"])
                ratios["memory"].append(ref["peak_mb"] / ours["peak_mb"])
                print(f"pair {pair + 1}: {describe('fieldapp', ours)}")
                print(f"        {describe('reference', ref)}")
        print(f"\nload average after: {load()}")
        print("reference / fieldapp, median (min-max) over all pairs:")
        for name, values in ratios.items():
            print(
                f"  {name:7s} {statistics.median(values):.2f} x "
                f"({min(values):.2f}-{max(values):.2f})"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
