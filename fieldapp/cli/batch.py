"""``fieldapp batch SESSION... --out DIR``: reconstruct many sessions on Dask (docs/BATCH.md)."""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fieldapp.cli.simulate import parse_int

if TYPE_CHECKING:
    from rich.console import Console

    from fieldapp.batch.plan import BatchPlan
    from fieldapp.batch.runner import BatchStatus, Outcome


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "batch",
        help="reconstruct many sessions on a Dask cluster (local by default)",
        description="Reconstruct each session as one Dask task, write its outputs into "
        "DIR/<session id>/ and record the run in the results database. Sessions already "
        "done with the same settings and fieldapp version are skipped; a failing session "
        "does not stop the others. Exit 1 when any session failed.",
    )
    parser.add_argument("sessions", type=Path, nargs="+", help="session folders")
    parser.add_argument("--out", type=Path, required=True, help="folder for the results")
    parser.add_argument("--scheduler", help="a Dask scheduler, e.g. tcp://host:8786")
    parser.add_argument(
        "--workers", default=str(usable_cpus()), help="local worker processes (the CPUs)"
    )
    parser.add_argument(
        "--memory-limit", default="auto", help="per local worker: auto (RAM / workers), 4GiB, 0"
    )
    parser.add_argument("--plot", help="the plot of every session (default: its own or its id)")
    parser.add_argument("--settings", type=Path, help="settings YAML (default: the user's)")
    parser.add_argument("--no-icp", action="store_true", help="keep the coarse station poses")
    parser.add_argument("--db", type=Path, help="the results database (default: settings)")
    parser.add_argument("--retries", default="2", help="retries of a task that raised (2)")
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    parser.set_defaults(handler=run)


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where the system has one)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def run(args: argparse.Namespace) -> int:
    from rich.console import Console

    from fieldapp import __version__
    from fieldapp.batch.cluster import memory_limit_bytes, open_client
    from fieldapp.batch.plan import plan_batch, task_settings
    from fieldapp.batch.runner import run_batch
    from fieldapp.results.db import ResultsDB
    from fieldapp.settings import load_settings

    workers = parse_int("workers", args.workers, 1, 1024)
    retries = parse_int("retries", args.retries, 0, 100)
    memory_limit = memory_limit_bytes(args.memory_limit)
    settings = load_settings(args.settings)
    if args.no_icp:
        settings.reconstruction.registration.enabled = False
    out_dir = args.out.resolve()
    console = Console(stderr=True, quiet=args.quiet)
    started_s = time.perf_counter()
    with ResultsDB.open(args.db or settings.paths.results_db) as db:
        data = task_settings(settings.reconstruction)
        plan = plan_batch(args.sessions, data, __version__, db, out_dir, args.plot)
        _announce(plan, console)
        outcomes: list[Outcome] = []
        if plan.to_run:
            with (
                open_client(args.scheduler, workers, memory_limit) as client,
                _display(console, len(plan.to_run)) as show_status,
            ):
                outcomes = run_batch(
                    client,
                    plan,
                    out_dir,
                    db,
                    retries=retries,
                    on_status=show_status,
                    on_outcome=lambda o: _print_outcome(o, console),
                )
    done = sum(o.status == "done" for o in outcomes)
    failed = len(outcomes) - done + len(plan.rejected)
    print(
        f"{done} done, {failed} failed, {len(plan.skipped)} already done "
        f"in {time.perf_counter() - started_s:.1f} s -> {out_dir}"
    )
    return 1 if failed else 0


def _announce(plan: BatchPlan, console: Console) -> None:
    for rejected in plan.rejected:
        print(f"failed: {rejected.session_dir}: {rejected.message}", file=sys.stderr)
    for item in plan.skipped:
        console.print(f"already done: {item.session_id}", highlight=False)
    console.print(
        f"{len(plan.to_run)} sessions to reconstruct, settings {plan.settings_sha256[:12]}, "
        f"fieldapp {plan.software_version}",
        highlight=False,
    )


def _print_outcome(outcome: Outcome, console: Console) -> None:
    if outcome.status == "failed":
        print(f"failed: {outcome.item.session_dir}: {outcome.message}", file=sys.stderr)
        return
    console.print(
        f"done: {outcome.item.session_id}: {outcome.plants} plants in {outcome.wall_s:.1f} s "
        f"({outcome.worker})",
        highlight=False,
    )


@contextmanager
def _display(console: Console, total: int) -> Iterator[Callable[[BatchStatus], None]]:
    """A rich progress bar with the batch's counts and time left (nothing when quiet); yields
    the function that shows a new status."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    bar = Progress(
        TextColumn("batch"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[counts]}"),
        console=console,
        disable=console.quiet,
    )
    task = bar.add_task("batch", total=total, counts=_counts(None))

    def show(status: BatchStatus) -> None:
        bar.update(task, completed=status.finished, counts=_counts(status))

    with bar:
        yield show


def _counts(status: BatchStatus | None) -> str:
    if status is None:
        return "waiting for the first session"
    left = status.time_left_s
    return (
        f"done {status.done} · failed {status.failed} · running {status.running} · "
        f"left {'?' if left is None else format_duration(left)}"
    )


def format_duration(seconds: float) -> str:
    """``75.0`` -> ``"1:15"``, ``3725.0`` -> ``"1:02:05"``."""
    whole = max(0, round(seconds))
    hours, rest = divmod(whole, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"
