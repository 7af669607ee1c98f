"""``fieldapp sim-base``: serve the simulated mobile base until interrupted."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "sim-base",
        help="run the simulated mobile base (fieldapp-base/1 server)",
        description="Serve the base protocol with a simulated base until Ctrl-C or SIGTERM. "
        "Prints the bound endpoints on its first line.",
    )
    parser.add_argument("--bind", default="tcp://127.0.0.1:5555", help="command endpoint")
    parser.add_argument("--telemetry", default="tcp://127.0.0.1:5556", help="telemetry endpoint")
    parser.add_argument(
        "--keys", type=Path, help="folder with base.key_secret, authorized_clients/"
    )
    parser.add_argument("--time-scale", type=float, default=1.0, help="simulated s per real s")
    parser.add_argument("--seed", type=int, default=0, help="seed of the arrival errors")
    parser.add_argument("--watchdog", type=float, default=1.0, help="lost-link timeout, seconds")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import zmq

    from devices.base.errors import BaseError
    from devices.base.keys import ServerKeys
    from devices.base.simulator import SimulatedBase

    done = threading.Event()
    # SIGINT too: a parent that ignores it (nohup, test runners' workers) passes that on
    for stop_signal in (signal.SIGINT, signal.SIGTERM):
        signal.signal(stop_signal, lambda _signum, _frame: done.set())
    try:
        keys = ServerKeys.from_dir(args.keys) if args.keys else None
        base = SimulatedBase(
            args.bind,
            args.telemetry,
            keys=keys,
            time_scale=args.time_scale,
            seed=args.seed,
            watchdog_s=args.watchdog,
        )
        base.start()
        # the spec: the authorised-keys folder is read again at once on SIGHUP (the default
        # action would end the base)
        signal.signal(signal.SIGHUP, lambda _signum, _frame: base.server.reload_keys())
    except (BaseError, OSError, zmq.ZMQError) as error:
        print(f"fieldapp sim-base: {error}", file=sys.stderr)
        return 1
    security = "CURVE" if keys else "no security, loopback only"
    endpoints = f"command {base.command_endpoint} telemetry {base.telemetry_endpoint}"
    print(f"sim-base: {endpoints} ({security})", flush=True)
    try:
        while not done.wait(0.2):
            pass
    finally:
        base.close()
    return 0
