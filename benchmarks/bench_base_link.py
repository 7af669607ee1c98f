"""Mobile base link timings on this machine, in real time, with the load: how long until a
revoked key is refused (new connections and the connection already made), until the base
stops itself once its commanding client falls silent (the lost-link watchdog), and until a
client reports a frozen base offline. Run by hand:
``.venv/bin/python benchmarks/bench_base_link.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import statistics
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from devices.base import (
    BaseAuthRejected,
    BaseError,
    ClientKeys,
    ClientTiming,
    Pose,
    ServerKeys,
    SimFault,
    SimulatedBase,
    generate_key_pair,
    open_base,
)
from devices.base.keys import AUTHORIZED_CLIENTS_DIR

ANY = "tcp://127.0.0.1:*"
QUICK = ClientTiming(request_timeout_s=0.2, retries=0)


def _key_folders(root: Path) -> tuple[Path, Path]:
    base, workstation = root / "base", root / "ws"
    generate_key_pair(base, "base")
    generate_key_pair(workstation, "client")
    (base / AUTHORIZED_CLIENTS_DIR).mkdir()
    shutil.copy(workstation / "client.key", base / AUTHORIZED_CLIENTS_DIR / "ws.key")
    shutil.copy(base / "base.key", workstation / "base.key")
    return base, workstation


def _until(predicate: Callable[[], bool], limit_s: float = 30.0) -> float:
    started_s = time.monotonic()
    while not predicate():
        if time.monotonic() - started_s > limit_s:
            return float("inf")
        time.sleep(0.005)
    return time.monotonic() - started_s


def revoked_key_s(old_connection: bool) -> float:
    """Seconds from removing the client's key file until a new connection with it is
    rejected, or (``old_connection``) until a request on a connection made before fails."""
    with tempfile.TemporaryDirectory() as folder:
        base_dir, ws_dir = _key_folders(Path(folder))
        keys = ClientKeys.from_dir(ws_dir)
        with SimulatedBase(ANY, ANY, keys=ServerKeys.from_dir(base_dir), time_scale=20.0) as sim:
            old = open_base(sim.command_endpoint, keys=keys, timing=QUICK)
            old.status()
            (base_dir / AUTHORIZED_CLIENTS_DIR / "ws.key").unlink()
            if old_connection:
                took_s = _until(lambda: _fails(old.status))
            else:
                took_s = _until(lambda: _rejected(sim.command_endpoint, keys))
            old.close()
            return took_s


def _fails(call: Callable[[], object]) -> bool:
    try:
        call()
    except BaseError:
        return True
    return False


def _rejected(endpoint: str, keys: ClientKeys) -> bool:
    client = open_base(endpoint, keys=keys, timing=QUICK)
    try:
        client.hello()
    except BaseAuthRejected:
        return True
    except BaseError:
        return False
    finally:
        client.close()
    return False


def lost_link_stop_s() -> float:
    """Seconds from the commanding client's last heartbeat to the base's stop latch."""
    with SimulatedBase(ANY, ANY, time_scale=0.2) as sim:
        client = open_base(sim.command_endpoint)
        client.goto("far", Pose(4.0, 0.0, 0.0), wait=False)
        time.sleep(0.5)
        client.close()  # heartbeats end: the link is lost
        silent_s = time.monotonic()
        _until(lambda: sim.latched)
        return time.monotonic() - silent_s


def offline_report_s() -> float:
    """Seconds from a base freezing to its client's follow_goal raising BaseOffline."""
    with SimulatedBase(ANY, ANY, time_scale=0.2) as sim:
        client = open_base(sim.command_endpoint)
        client.goto("far", Pose(4.0, 0.0, 0.0), wait=False)
        raised = threading.Event()

        def follow() -> None:
            try:
                for _ in client.follow_goal("far", 60.0):
                    pass
            except BaseError:
                raised.set()

        thread = threading.Thread(target=follow)
        thread.start()
        time.sleep(0.3)
        sim.inject_fault(SimFault.FREEZE)
        frozen_s = time.monotonic()
        raised.wait(30.0)
        took_s = time.monotonic() - frozen_s
        thread.join()
        client.close()
        return took_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    print(f"load average before: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} cores")
    rows = {
        "revoked key: new connection rejected after": [
            revoked_key_s(False) for _ in range(args.repeats)
        ],
        "revoked key: request on an old connection fails after": [
            revoked_key_s(True) for _ in range(args.repeats)
        ],
        "lost link: base stopped after": [lost_link_stop_s() for _ in range(args.repeats)],
        "frozen base: reported offline after": [offline_report_s() for _ in range(args.repeats)],
    }
    for name, values in rows.items():
        print(f"{name}: median {statistics.median(values):.2f} s, max {max(values):.2f} s")
    print(f"load average after: {os.getloadavg()[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
