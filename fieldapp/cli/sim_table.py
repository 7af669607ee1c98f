"""``fieldapp sim-table``: serve a simulated Grbl table controller on a pseudo-terminal."""

from __future__ import annotations

import argparse
import signal
import sys
import time
from types import FrameType
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "sim-table",
        help="serve a simulated rotary table (Grbl 1.1) on a pseudo-terminal",
        description="Start a simulated Grbl 1.1 table controller on a pseudo-terminal, print "
        "its device path, and serve until Ctrl-C. Point `fieldapp table --port` (or the app's "
        "devices.table_port setting) at the printed path.",
    )
    parser.add_argument(
        "--realtime", action="store_true", help="move in real time (default: instantly)"
    )
    parser.add_argument(
        "--off-target-deg",
        type=float,
        default=0.0,
        help="stop up to this many degrees off each target (seeded noise; default 0)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated noise")
    parser.add_argument(
        "--homing", action="store_true", help="enable homing ($22=1): starts locked in Alarm"
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from devices.table import GrblSimulator, PtyGrblServer

    simulator = GrblSimulator(
        settings={22: 1} if args.homing else None,
        off_target_deg=args.off_target_deg,
        seed=args.seed,
    )
    server = PtyGrblServer(simulator, time_scale=1.0 if args.realtime else 0.0).start()
    print(server.device_path, flush=True)
    mode = "real time" if args.realtime else "instant moves"
    print(f"simulated Grbl table ({mode}); Ctrl-C to stop", file=sys.stderr, flush=True)
    # Ctrl-C stops it even when the parent started it with SIGINT ignored (nohup, test
    # runners' workers): Python then installs no handler of its own.
    for stop_signal in (signal.SIGINT, signal.SIGTERM):
        signal.signal(stop_signal, _interrupt)
    try:
        while server.running:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    return 0


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt
