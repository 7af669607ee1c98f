"""The base client's transports on this machine, in real time, with the load: a request's round
trip (``heartbeat``) and a client's open + ``hello`` + close, to a simulated base in process
(``inproc://``), on loopback TCP, and on loopback TCP with CURVE. Run by hand:
``.venv/bin/python benchmarks/bench_base_transport.py [--requests N] [--clients N]``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import zmq

from devices.base import ClientKeys, ServerKeys, SimulatedBase, generate_key_pair, open_base
from devices.base.keys import AUTHORIZED_CLIENTS_DIR
from devices.base.transport import new_inproc_endpoints

ANY = "tcp://127.0.0.1:*"


def _keys(root: Path) -> tuple[ServerKeys, ClientKeys]:
    base, workstation = root / "base", root / "ws"
    generate_key_pair(base, "base")
    generate_key_pair(workstation, "client")
    (base / AUTHORIZED_CLIENTS_DIR).mkdir()
    shutil.copy(workstation / "client.key", base / AUTHORIZED_CLIENTS_DIR / "ws.key")
    shutil.copy(base / "base.key", workstation / "base.key")
    return ServerKeys.from_dir(base), ClientKeys.from_dir(workstation)


def measure(kind: str, requests: int, clients: int) -> tuple[float, float]:
    """(median heartbeat round trip, median open + hello + close), in ms."""
    context: zmq.Context[zmq.Socket[bytes]] | None = None
    server_keys = client_keys = None
    with tempfile.TemporaryDirectory() as folder:
        if kind == "inproc":
            context = zmq.Context()
            endpoints = new_inproc_endpoints("bench")
        else:
            endpoints = (ANY, ANY)
            if kind == "tcp+curve":
                server_keys, client_keys = _keys(Path(folder))
        sim = SimulatedBase(*endpoints, keys=server_keys, context=context).start()
        try:
            with open_base(sim.command_endpoint, keys=client_keys, context=context) as client:
                client.hello()
                trips_ms = []
                for _ in range(requests):
                    started_s = time.perf_counter()
                    client.heartbeat()
                    trips_ms.append((time.perf_counter() - started_s) * 1000)
            opens_ms = []
            for _ in range(clients):
                started_s = time.perf_counter()
                with open_base(sim.command_endpoint, keys=client_keys, context=context) as c:
                    c.hello()
                opens_ms.append((time.perf_counter() - started_s) * 1000)
        finally:
            sim.close()
            if context is not None:
                context.term()
    return statistics.median(trips_ms), statistics.median(opens_ms)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--requests", type=int, default=500)
    parser.add_argument("--clients", type=int, default=20)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} (1 min), {os.cpu_count()} cores")
    for kind in ("inproc", "tcp", "tcp+curve"):
        trip_ms, open_ms = measure(kind, args.requests, args.clients)
        print(f"{kind:10s} round trip {trip_ms:6.2f} ms   open + hello + close {open_ms:6.1f} ms")
    print(f"load average {os.getloadavg()[0]:.1f} (1 min)")


if __name__ == "__main__":
    main()
