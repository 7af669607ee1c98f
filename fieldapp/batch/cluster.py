# mypy: disable-error-code="no-untyped-call"
# (distributed leaves much of its API unannotated)
"""Where a batch runs: a local Dask cluster (the default) or an existing scheduler.

The local cluster has ``workers`` worker processes with one thread each, so a worker holds one
session at a time, and a nanny per worker that restarts it when it dies or passes its
``memory_limit``. Dask's own logging is kept off the terminal (the client's errors only; the
local workers' not even those: the client reports each failed session), and the local workers
log only fieldapp's errors: each session's warnings are in its ``report.json``.

Every worker, local or remote, gets glibc's large allocation thresholds back
(:class:`GlibcMallocThresholds`): Dask's nanny starts workers with
``MALLOC_TRIM_THRESHOLD_=65536``, which also pins glibc's mmap threshold at 128 KiB, so each
of the pipeline's large temporary arrays was mapped, page-faulted and unmapped anew. That cost
a reconstruction 30 % more CPU on a worker than in ``fieldapp reconstruct`` (3.9 s against
3.0 s per 72-capture session, measured).
"""

from __future__ import annotations

import asyncio
import ctypes
import logging
import os
import platform
from collections.abc import Iterator
from contextlib import contextmanager

from dask.utils import parse_bytes
from distributed import Client, LocalCluster
from distributed.comm.core import connect
from distributed.diagnostics.plugin import WorkerPlugin
from distributed.security import Security

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


class GlibcMallocThresholds(WorkerPlugin):
    """Worker plugin: glibc keeps freed large blocks for reuse again, as in a plain process.

    Setting ``MALLOC_TRIM_THRESHOLD_`` (Dask's default for nanny-started workers) turns off
    glibc's sliding mmap threshold: every block over 128 KiB is then a fresh ``mmap``, whose
    pages fault in one by one when first written. This sets the thresholds the sliding
    scheme would reach (mmap at 32 MiB, trim at 64 MiB). Memory stays bounded: blocks over
    32 MiB are still unmapped on free, and at most 64 MiB of free heap top is kept. Does
    nothing where the C library is not glibc, or where the worker's environment leaves the
    thresholds alone.
    """

    name = "fieldapp-glibc-malloc-thresholds"
    M_TRIM_THRESHOLD = -1
    M_MMAP_THRESHOLD = -3
    MMAP_THRESHOLD_BYTES = 32 * 2**20
    TRIM_THRESHOLD_BYTES = 64 * 2**20

    def setup(self, worker: object) -> None:
        applied = self.apply()
        log.debug("malloc thresholds %s", "set" if applied else "left alone")

    @classmethod
    def apply(cls) -> bool:
        """Set the thresholds in this process; whether they were set."""
        pinned = "MALLOC_TRIM_THRESHOLD_" in os.environ or "MALLOC_MMAP_THRESHOLD_" in os.environ
        if not pinned or platform.libc_ver()[0] != "glibc":
            return False
        try:
            libc = ctypes.CDLL(None)
            done = libc.mallopt(cls.M_MMAP_THRESHOLD, cls.MMAP_THRESHOLD_BYTES)
            done &= libc.mallopt(cls.M_TRIM_THRESHOLD, cls.TRIM_THRESHOLD_BYTES)
        except (OSError, AttributeError):
            return False
        return bool(done)


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
                client.register_plugin(GlibcMallocThresholds())
                yield client
            return
        with _local_cluster(workers, memory_limit) as cluster, Client(cluster) as client:
            client.register_plugin(QuietFieldappLogs())
            client.register_plugin(GlibcMallocThresholds())
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


async def _probe(address: str, timeout_s: float) -> None:
    comm = await connect(address, timeout=timeout_s, **Security().get_connection_args("client"))
    await comm.close()


@contextmanager
def _connect(address: str, timeout_s: float) -> Iterator[Client]:
    """A client of the scheduler at ``address``. The address is tried with a bare connection
    first: a :class:`Client` whose constructor fails leaves a half-built object whose
    ``__del__`` later raises a ``TimeoutError`` of its own (ignored, but noise)."""
    try:
        asyncio.run(_probe(address, timeout_s))
        client = Client(address, timeout=timeout_s)
    except (OSError, ValueError, TypeError) as error:
        raise BatchError(f"--scheduler: cannot reach {address}: {error}") from None
    with client:
        log.info("scheduler %s: %d workers", address, len(client.nthreads()))
        yield client
