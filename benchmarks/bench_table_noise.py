"""Rotary table under line noise: how long a failure takes to be reported, and whether any turn
ever reports a wrong angle. Run by hand (real time, with the machine's load):
``.venv/bin/python benchmarks/bench_table_noise.py [--turns N] [--seeds 0 1 2]``.

Each turn goes to a random angle on the simulated Grbl controller behind a real pty; before a
turn, with probability ``--noise``, one of the controller's next few output lines is garbled
(the status, an ``ok``, a poll's answer). A turn that raises is a reported failure, timed from
the call; a turn that returns must return the angle the table is really at (within 0.2 deg).
"""

from __future__ import annotations

import argparse
import logging
import os
import random
import statistics
import time

import serial

from devices.table import GrblSimulator, GrblTable, PtyGrblServer, TableException, TableTimeouts


def run_seed(seed: int, turns: int, noise: float) -> tuple[list[float], list[float], int]:
    """(failure report times, successful turn times, wrong angles) for one seed."""
    rng = random.Random(seed)
    server = PtyGrblServer(GrblSimulator(seed=seed)).start()
    port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=0.05)
    table = GrblTable(port, timeouts=TableTimeouts())
    failures_s: list[float] = []
    turns_s: list[float] = []
    wrong = 0
    try:
        table.connect()
        for _ in range(turns):
            if rng.random() < noise:
                server.simulator.garble(count=1, skip=rng.randint(0, 4))
            target_deg = round(rng.uniform(-180.0, 180.0), 3)
            started_s = time.monotonic()
            try:
                reached_deg = table.goto_deg(target_deg)
            except TableException:
                failures_s.append(time.monotonic() - started_s)
                continue
            turns_s.append(time.monotonic() - started_s)
            if abs(reached_deg - server.simulator.angle_deg) > 0.2:
                wrong += 1
    finally:
        table.close()
        server.close()
    return failures_s, turns_s, wrong


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--turns", type=int, default=300)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--noise", type=float, default=0.3, help="share of noisy turns")
    args = parser.parse_args()
    logging.disable(logging.WARNING)  # the driver logs every garbled line
    print(f"load average before: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} cores")
    for seed in args.seeds:
        failures_s, turns_s, wrong = run_seed(seed, args.turns, args.noise)
        worst = max(failures_s, default=0.0)
        median = statistics.median(failures_s) if failures_s else 0.0
        print(
            f"seed {seed}: {args.turns} turns, {len(failures_s)} failures reported in "
            f"median {median:.2f} s, max {worst:.2f} s; successful turns median "
            f"{statistics.median(turns_s):.3f} s; wrong angles: {wrong}"
        )
    print(f"load average after: {os.getloadavg()[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
