"""GUI responsiveness while the results panel reconstructs a session on its worker.

A 10 ms QTimer ticks on the GUI thread during the reconstruction; a stall is a tick that came
late (the gap between ticks minus the period). Prints the reconstruction's wall time and the
stall distribution; the bound is 50 ms.

    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/bench_workstation_latency.py \
        [--stations 1-9] [--views 0-7] [--session DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

PERIOD_MS = 10
BOUND_MS = 50.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stations", default="4,5,6")
    parser.add_argument("--views", default="0-7")
    parser.add_argument("--session", type=Path, help="an existing session (else simulated)")
    args = parser.parse_args()
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication([])
    with tempfile.TemporaryDirectory() as tmp:
        session = args.session or simulate(Path(tmp) / "session", args.stations, args.views)
        gaps_ms, wall_s, plants = measure(app, session, Path(tmp) / "results")
    stalls = np.maximum(np.asarray(gaps_ms) - PERIOD_MS, 0.0)
    print(f"session {session.name}: {plants} plants, reconstruction {wall_s:.1f} s wall")
    print(f"GUI ticks: {len(gaps_ms)} (every {PERIOD_MS} ms asked)")
    for q in (50, 95, 99, 100):
        print(f"  stall p{q}: {np.percentile(stalls, q):.1f} ms")
    over = int((stalls > BOUND_MS).sum())
    print(f"  stalls over {BOUND_MS:.0f} ms: {over}  -> {'OK' if over == 0 else 'OVER BOUND'}")
    return 0


def simulate(folder: Path, stations: str, views: str) -> Path:
    from fieldapp.cli import main as cli

    if cli(["simulate", "--out", str(folder), "--stations", stations, "--views", views]) != 0:
        raise SystemExit("simulation failed")
    return folder


def measure(
    app: QtWidgets.QApplication, session: Path, out: Path
) -> tuple[list[float], float, int]:
    from ui.results import ResultsPanel

    panel = ResultsPanel()
    panel.resize(1200, 800)
    panel.show()
    panel.open_session(session)
    panel.results_dir.setText(str(out))
    gaps: list[float] = []
    last = [time.perf_counter()]

    def tick() -> None:
        now = time.perf_counter()
        gaps.append(1000 * (now - last[0]))
        last[0] = now

    timer = QtCore.QTimer()
    timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
    timer.timeout.connect(tick)
    timer.start(PERIOD_MS)
    started = time.perf_counter()
    panel.reconstruct()
    panel.runner.wait(600)
    wall = time.perf_counter() - started
    timer.stop()
    plants = len(panel.results.plants) if panel.results else 0
    panel.close()
    return gaps[1:], wall, plants


if __name__ == "__main__":
    raise SystemExit(main())
