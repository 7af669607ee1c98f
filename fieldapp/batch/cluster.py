# mypy: disable-error-code="no-untyped-call"
# (distributed leaves much of its API unannotated)
"""Where a batch runs: a local Dask cluster (the default) or an existing scheduler.

The local cluster has ``workers`` worker processes with one thread each, so a worker holds one
session at a time, and a nanny per worker that restarts it when it dies or passes its
``memory_limit``. Dask's own logging is kept off the terminal (the client's errors only; the
local workers' not even those: the client reports each failed session), and the local workers
log only fieldapp's errors: each session's warnings are in its ``report.json``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

from dask.utils import parse_bytes
from distributed import Client, LocalCluster
from distributed.diagnostics.plugin import WorkerPlugin

from fieldapp.batch.task import BatchError

log = logging.getLogger(__name__)

DASK_LOGGERS = ("distributed", "tornado", "bokeh")
CONNECT_TIMEOUT_S = 20.0


def memory_limit_bytes(text: str) -> str | int:
    """``"auto"`` (the machine's memory shared between the workers), ``"0"`` (no limit) or a
    size such as ``"4GiB"``, in bytes; raises :class:`BatchError` naming the option."""
    text = text.strip()
    if text.lower() == "auto":
        return "auto"
    try:
        value = int(parse_bytes(text)) if text else -1
    except (ValueError, TypeError):
        raise BatchError(f"--memory-limit: {text!r} is not a size (e.g. 4GiB, auto)") from None
    if value < 0:
        raise BatchError(f"--memory-limit: {text!r} is not a size (e.g. 4GiB, auto)")
    return value


@contextmanager
def quiet_dask_logging(level: int = logging.ERROR) -> Iterator[None]:
    """Dask's loggers in this process at ``level`` (default: errors only) while inside."""
    loggers = [logging.getLogger(name) for name in DASK_LOGGERS]
    before = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(level)
    try:
        yield
    finally:
        for logger, old in zip(loggers, before, strict=True):
            logger.setLevel(old)


class QuietFieldappLogs(WorkerPlugin):
    """Worker plugin: the worker logs only fieldapp's errors (warnings go into reports)."""

    name = "fieldapp-quiet-logs"

    def setup(self, worker: object) -> None:
        logging.getLogger("fieldapp").setLevel(logging.ERROR)


@contextmanager
def open_client(
    scheduler: str | None,
    workers: int,
    memory_limit: str | int = "auto",
    connect_timeout_s: float = CONNECT_TIMEOUT_S,
) -> Iterator[Client]:
    """A Dask client: of the scheduler at ``scheduler`` (``tcp://host:8786``), or of a new
    local cluster of ``workers`` single-threaded worker processes. Closed on exit."""
    if workers < 1:
        raise BatchError(f"--workers: {workers} must be at least 1")
    with quiet_dask_logging():
        if scheduler is not None:
            with _connect(scheduler, connect_timeout_s) as client:
                yield client
            return
        with _local_cluster(workers, memory_limit) as cluster, Client(cluster) as client:
            client.register_plugin(QuietFieldappLogs())
            log.info(
                "local cluster of %d workers: %s, dashboard %s",
                workers,
                cluster.scheduler_address,
                client.dashboard_link,
            )
            yield client


def _local_cluster(workers: int, memory_limit: str | int) -> LocalCluster:
    """Started, or a :class:`BatchError` saying why not (e.g. a script without a
    ``__main__`` guard: worker processes are spawned and import the main module)."""
    try:
        return LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            memory_limit=memory_limit,
            host="127.0.0.1",
            dashboard_address=":0",  # any free port: 8787 may be another cluster's
            silence_logs=logging.CRITICAL,  # a task's error is reported by the client
        )
    except (RuntimeError, OSError, ValueError) as error:
        raise BatchError(f"cannot start a local cluster of {workers} workers: {error}") from None


@contextmanager
def _connect(address: str, timeout_s: float) -> Iterator[Client]:
    try:
        client = Client(address, timeout=timeout_s)
    except (OSError, ValueError, TypeError) as error:
        raise BatchError(f"--scheduler: cannot reach {address}: {error}") from None
    with client:
        log.info("scheduler %s: %d workers", address, len(client.nthreads()))
        yield client
