"""How reconstruction cost grows with the plot: 3 x 3 to 9 x 9 stations.

    .venv/bin/python benchmarks/bench_scaling.py [--grids 3,5,7] [--seed 1] [--keep DIR]

For each grid size G, a simulated plot of G x G stations (``fieldapp simulate --grid G``; 8
views each, plants spread over it) is reconstructed by ``fieldapp reconstruct`` in its own
process, as a user runs it. Per plot: stations, plants found, wall time, CPU time (user +
system, every thread) and peak resident memory from the process's rusage, and per station
and per plant the CPU and memory above the 3 x 3 plot's (the growth, without the fixed cost
of start-up). The load average is printed around each run: on a shared machine the wall
times follow the load, CPU time and memory much less. Sessions are simulated into
``--keep DIR`` (reused when already there) or a temporary folder.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_reconstruct import FIELDAPP, load, measured


def simulated(root: Path, grid: int, seed: int) -> Path:
    """The G x G plot session of ``seed`` under ``root``, simulated unless already there."""
    folder = root / f"grid{grid}-seed{seed}"
    if not (folder / "session.json").is_file():
        argv = [str(FIELDAPP), "simulate", "--out", str(folder), "--seed", str(seed)]
        subprocess.run([*argv, "--grid", str(grid)], check=True, capture_output=True)
    return folder


def reconstructed(session: Path, out: Path) -> dict[str, Any]:
    """``fieldapp reconstruct`` of ``session``: wall, CPU, peak MB, stations, plants and
    the CPU seconds of each stage (its ``report.json``)."""
    argv = [str(FIELDAPP), "reconstruct", str(session), "--out", str(out), "--quiet"]
    figures = measured(argv)
    report = json.loads((out / "report.json").read_text())
    figures["stations"] = len(report["stations"])
    figures["plants"] = report["plants"]
    figures["stages"] = report["cpu_s"]
    figures["fused"] = report["points_kept"]["fused"]
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grids", default="3,5,7", help="stations per side, e.g. 3,5,7,9")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--keep", type=Path, help="simulate into (and reuse) this folder")
    args = parser.parse_args()
    grids = [int(g) for g in args.grids.split(",")]
    with tempfile.TemporaryDirectory() as scratch_name:
        root = args.keep or Path(scratch_name)
        sessions = {grid: simulated(root, grid, args.seed) for grid in grids}
        print(f"{os.cpu_count()} CPUs; seed {args.seed}")
        print("grid stations plants   wall s   CPU s  peak MB  load before/after")
        rows = []
        for grid, session in sessions.items():
            before = load()
            out = Path(tempfile.mkdtemp(dir=scratch_name))
            f = reconstructed(session, out)
            rows.append(f)
            print(
                f"{grid:4d} {f['stations']:8.0f} {f['plants']:6.0f} {f['wall_s']:8.2f} "
                f"{f['cpu_s']:7.2f} {f['peak_mb']:8.0f}  {before} / {load()}"
            )
        print("CPU s per stage:")
        for grid, f in zip(grids, rows, strict=True):
            stages = ", ".join(f"{name} {cpu:.2f}" for name, cpu in f["stages"].items())
            print(f"  grid {grid} ({f['fused']} fused points): {stages}")
        first = rows[0]
        print("growth over the first plot, per added station and per added plant:")
        for grid, f in zip(grids[1:], rows[1:], strict=True):
            stations, plants = f["stations"] - first["stations"], f["plants"] - first["plants"]
            cpu, memory = f["cpu_s"] - first["cpu_s"], f["peak_mb"] - first["peak_mb"]
            print(
                f"  grid {grid}: {cpu / stations:.2f} s CPU and {memory / stations:.1f} MB per "
                f"station; {cpu / max(plants, 1):.2f} s and {memory / max(plants, 1):.1f} MB "
                "per plant"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
