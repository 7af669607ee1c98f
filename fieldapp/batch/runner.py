# mypy: disable-error-code="no-untyped-call"
# (distributed leaves much of its API unannotated)
"""Run a planned batch on a Dask client: one task per session, results recorded as they come.

Only this process (the client) writes to the results database: a finished session's run is
recorded with :meth:`ResultsDB.record_run` (a failed one with ``record_failure``) the moment
its future completes, so an interrupted batch keeps every run that finished, and the next run
of the same command skips them. A session that fails never stops the others.
"""

from __future__ import annotations

import logging
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from distributed import Client, Future, wait

from fieldapp.batch.plan import BatchItem, BatchPlan
from fieldapp.batch.task import SessionSummary, reconstruct_session
from fieldapp.errors import FieldappError
from fieldapp.results.db import ResultsDB

log = logging.getLogger(__name__)

DEFAULT_RETRIES = 2
TICK_S = 0.5

Status = Literal["done", "failed"]
TaskFuture = Future[SessionSummary]


@dataclass(frozen=True)
class Outcome:
    """How one submitted session ended. ``run_id``: its row in the results database."""

    item: BatchItem
    status: Status
    message: str
    plants: int = 0
    wall_s: float = 0.0
    worker: str = ""
    run_id: int | None = None


@dataclass(frozen=True)
class BatchStatus:
    """Counts of the submitted sessions at one moment; ``running`` is at most one per worker
    thread (the rest wait in the scheduler's queue)."""

    total: int
    done: int
    failed: int
    running: int
    elapsed_s: float

    @property
    def finished(self) -> int:
        return self.done + self.failed

    @property
    def time_left_s(self) -> float | None:
        """The remaining sessions at the pace so far; ``None`` before the first one ends."""
        if self.finished == 0:
            return None
        return self.elapsed_s / self.finished * (self.total - self.finished)


Task = Callable[[str, Mapping[str, Any], str], SessionSummary]
"""What a task runs: (session folder, settings data, output folder) -> summary."""
OnStatus = Callable[[BatchStatus], None]
OnOutcome = Callable[[Outcome], None]


def run_batch(
    client: Client,
    plan: BatchPlan,
    out_dir: Path,
    db: ResultsDB,
    *,
    retries: int = DEFAULT_RETRIES,
    on_status: OnStatus | None = None,
    on_outcome: OnOutcome | None = None,
    task: Task = reconstruct_session,
) -> list[Outcome]:
    """Reconstruct ``plan.to_run`` on ``client``'s cluster; returns the outcomes in the order
    the sessions finished. ``on_status`` is called about twice a second and after each
    session, ``on_outcome`` once per session. ``task`` is what each task runs (tests give a
    stand-in)."""
    started_s = time.perf_counter()
    futures = _submit(client, task, plan, out_dir.resolve(), retries)
    items = {future.key: item for future, item in futures.items()}
    outcomes: list[Outcome] = []
    pending = set(futures)
    while pending:
        finished, pending = _wait_some(pending)
        for future in finished:
            outcome = _record(db, plan, items[future.key], _summary_of(future))
            future.release()
            outcomes.append(outcome)
            if on_outcome is not None:
                on_outcome(outcome)
        if on_status is not None:
            on_status(_status(client, len(futures), outcomes, len(pending), started_s))
    return outcomes


def _submit(
    client: Client, task: Task, plan: BatchPlan, out_dir: Path, retries: int
) -> dict[TaskFuture, BatchItem]:
    batch = uuid.uuid4().hex[:8]
    return {
        client.submit(
            task,
            str(item.session_dir),
            plan.settings,
            str(out_dir),
            key=f"fieldapp-batch-{batch}-{index:05d}",
            pure=False,
            retries=retries,
        ): item
        for index, item in enumerate(plan.to_run)
    }


def _wait_some(pending: set[TaskFuture]) -> tuple[set[TaskFuture], set[TaskFuture]]:
    """(finished, still pending) after at most :data:`TICK_S`."""
    try:
        done, not_done = wait(list(pending), timeout=TICK_S, return_when="FIRST_COMPLETED")
    except TimeoutError:
        return set(), pending
    return set(done), set(not_done)


def _summary_of(future: TaskFuture) -> SessionSummary | str:
    """The task's summary, or the message of what it raised (after its retries)."""
    if future.status == "error":
        error = future.exception()
        return f"{type(error).__name__}: {error}"
    if future.status == "cancelled":
        return "cancelled"
    try:
        return future.result()
    except Exception as error:  # lost between completion and gathering, and not recomputed
        return f"{type(error).__name__}: {error}"


def _record(
    db: ResultsDB, plan: BatchPlan, item: BatchItem, summary: SessionSummary | str
) -> Outcome:
    """Record the session's run (or failure) in the database; the session's outcome."""
    if isinstance(summary, str):
        return _record_failure(db, plan, item, summary, None)
    problem = _summary_problem(plan, item, summary)
    if problem:
        return _record_failure(db, plan, item, problem, summary)
    try:
        run_id = db.record_run(
            item.plot,
            item.session_dir,
            Path(summary.results_dir),
            settings=plan.settings,
            software_version=plan.software_version,
        )
    except FieldappError as error:
        return _record_failure(db, plan, item, f"recording the run: {error}", summary)
    return Outcome(item, "done", "", summary.plants, summary.wall_s, summary.worker, run_id=run_id)


def _summary_problem(plan: BatchPlan, item: BatchItem, summary: SessionSummary) -> str:
    if not summary.ok:
        return summary.message
    if summary.session_id != item.session_id:
        return f"the session's id changed from {item.session_id!r} to {summary.session_id!r}"
    if summary.software_version != plan.software_version:
        return (
            f"worker {summary.worker} runs fieldapp {summary.software_version}, "
            f"this client {plan.software_version}: install the same version on every worker"
        )
    return ""


def _record_failure(
    db: ResultsDB,
    plan: BatchPlan,
    item: BatchItem,
    message: str,
    summary: SessionSummary | None,
) -> Outcome:
    log.warning("%s: %s", item.session_id, message)
    run_id: int | None = None
    try:
        run_id = db.record_failure(
            item.plot,
            item.session_dir,
            message,
            settings=plan.settings,
            software_version=plan.software_version,
        )
    except FieldappError as error:
        log.warning("%s: failure not recorded: %s", item.session_id, error)
    wall_s = summary.wall_s if summary else 0.0
    worker = summary.worker if summary else ""
    return Outcome(item, "failed", message, 0, wall_s, worker, run_id=run_id)


def _status(
    client: Client, total: int, outcomes: list[Outcome], pending: int, started_s: float
) -> BatchStatus:
    threads = sum(client.nthreads().values())
    return BatchStatus(
        total=total,
        done=sum(o.status == "done" for o in outcomes),
        failed=sum(o.status == "failed" for o in outcomes),
        running=min(pending, threads),
        elapsed_s=time.perf_counter() - started_s,
    )
