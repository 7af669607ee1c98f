"""Start-up time of the field GUI: from process start to the first window shown.

Runs ``python -m fieldapp gui`` (the real command, offscreen unless ``DISPLAY`` is set) ``--runs``
times with ``FIELDAPP_STARTUP_PROBE`` set: once the event loop has shown and painted the window,
the application writes the monotonic time and closes (``ui/app.py``). CLOCK_MONOTONIC is one
clock for every process on Linux, so the time is measured from just before the process is
spawned. The process's CPU time is reported too: on a busy machine the wall time mostly
measures the wait for a core, the CPU time what the start-up costs. Each run has its own empty
settings and config folders (a first start). Prints every run, the median and the worst, the
1-minute load average before and after, and which heavy modules (Open3D, SciPy, matplotlib,
Dask, OpenCV) were loaded by then (target: none; start-up within 3 s on a quiet 2-core
machine).

With ``--reconstruct`` it measures the start-up of ``fieldapp reconstruct`` instead (issue 22):
the CPU and wall time of ``fieldapp reconstruct --help`` (no heavy import), of a process
importing what a quiet reconstruction imports before its first stage (the pipeline, numpy,
SciPy, OpenCV, small_gicp, pydantic), the difference being what the run itself starts with,
and of one importing only the libraries a run needs (numpy, SciPy, OpenCV, small_gicp).

    .venv/bin/python benchmarks/bench_startup.py --runs 5
    .venv/bin/python benchmarks/bench_startup.py --runs 5 --reconstruct
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 3.0
RECONSTRUCT_IMPORTS = (
    "import fieldapp.cli; from fieldapp.cli import reconstruct; import "
    "fieldapp.io.session, fieldapp.provenance, fieldapp.recon.outputs, "
    "fieldapp.recon.pipeline, fieldapp.settings"
)
"""What ``fieldapp reconstruct --quiet`` imports before its first stage (the progress bar of a
run without ``--quiet`` adds rich.progress, about 0.07 s)."""
SCIPY_FLOOR = (
    "import fieldapp.cli._blas, numpy, scipy.spatial, scipy.sparse.csgraph, scipy.ndimage, "
    "cv2, small_gicp"
)
"""The libraries every reconstruction needs (k-d trees, graphs, labelling, decoding, GICP):
what deferring fieldapp's own imports cannot save. SciPy's array-API layer walks every
attribute of numpy on import, loading numpy.f2py, numpy.testing, numpy.random and numpy.ma."""


def one_start(folder: Path) -> tuple[float, float, list[str]]:
    """(seconds to the first window, CPU seconds the process used, heavy modules loaded)."""
    probe = folder / "probe.json"
    env = dict(os.environ)
    env.update(
        FIELDAPP_STARTUP_PROBE=str(probe),
        XDG_CONFIG_HOME=str(folder / "config"),
        XDG_DATA_HOME=str(folder / "data"),
    )
    if "DISPLAY" not in env:
        env["QT_QPA_PLATFORM"] = "offscreen"
    command = [sys.executable, "-m", "fieldapp", "gui", "--settings", str(folder / "s.yaml")]
    cpu_before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started_s = time.monotonic()
    subprocess.run(command, env=env, check=True, capture_output=True, timeout=300)
    cpu_after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (cpu_after.ru_utime - cpu_before.ru_utime) + (cpu_after.ru_stime - cpu_before.ru_stime)
    shown = json.loads(probe.read_text())
    return shown["shown_s"] - started_s, cpu_s, shown["heavy_modules"]


def timed(command: list[str]) -> tuple[float, float]:
    """(wall seconds, CPU seconds) of one run of ``command``."""
    cpu_before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started_s = time.monotonic()
    subprocess.run(command, check=True, capture_output=True, timeout=300)
    elapsed_s = time.monotonic() - started_s
    cpu_after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (cpu_after.ru_utime - cpu_before.ru_utime) + (cpu_after.ru_stime - cpu_before.ru_stime)
    return elapsed_s, cpu_s


def reconstruct_startup(runs: int) -> int:
    """Start-up of ``fieldapp reconstruct``: its help, and the imports of a run."""
    commands = {
        "fieldapp reconstruct --help": [sys.executable, "-m", "fieldapp", "reconstruct", "--help"],
        "imports of a quiet reconstruction": [sys.executable, "-c", RECONSTRUCT_IMPORTS],
        "of which the libraries it needs": [sys.executable, "-c", SCIPY_FLOOR],
    }
    load_before = os.getloadavg()[0]
    for name, command in commands.items():
        results = [timed(command) for _ in range(runs)]
        walls, cpus = [w for w, _ in results], [c for _, c in results]
        print(
            f"{name}: CPU median {statistics.median(cpus):.2f} s (best {min(cpus):.2f}), "
            f"wall median {statistics.median(walls):.2f} s (best {min(walls):.2f}), {runs} runs"
        )
    print(f"{os.cpu_count()} CPUs, load average {load_before:.1f} -> {os.getloadavg()[0]:.1f}")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument(
        "--reconstruct", action="store_true", help="the start-up of fieldapp reconstruct"
    )
    args = parser.parse_args()
    if args.reconstruct:
        return reconstruct_startup(args.runs)
    load_before = os.getloadavg()[0]
    times_s, cpus_s = [], []
    heavy: set[str] = set()
    for run in range(1, args.runs + 1):
        with tempfile.TemporaryDirectory() as tmp:
            elapsed_s, cpu_s, modules = one_start(Path(tmp))
        times_s.append(elapsed_s)
        cpus_s.append(cpu_s)
        heavy.update(modules)
        print(
            f"run {run}: first window after {elapsed_s:.2f} s, CPU {cpu_s:.2f} s "
            f"(heavy modules: {', '.join(modules) or 'none'})"
        )
    load_after = os.getloadavg()[0]
    print(
        f"median {statistics.median(times_s):.2f} s, best {min(times_s):.2f} s, worst "
        f"{max(times_s):.2f} s over {args.runs} runs (target {TARGET_S:.0f} s); "
        f"{os.cpu_count()} CPUs, load average {load_before:.1f} -> {load_after:.1f}"
    )
    print(
        f"CPU time per start (the whole process, closing included): median "
        f"{statistics.median(cpus_s):.2f} s, about the wall time on an idle machine"
    )
    print(f"heavy modules loaded before the first window: {sorted(heavy) or 'none'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
