"""Work that holds Python's GIL on two cores: this process and one forked worker share it.

GICP (small_gicp) holds the GIL for the whole of a call, and much of the organ step is short
numpy and SciPy calls, so pairs or plants on Python threads run one after the other whatever the
thread count; only a second process runs a second one at the same time. With ``threads`` of 2
or more, :class:`ForkedMap` forks one worker process when a stage starts: the modules are
already imported, so it is ready in milliseconds and costs no start-up CPU. :meth:`ForkedMap.map`
gives the worker the items from the front of the list and runs them here from the back, until
the two meet; every item is the same function of the same inputs wherever it runs (one OpenMP
thread each: registration's fits do not depend on the thread count, see :mod:`pairwise`), so
the results, in order, are those of one process.

Where no worker can be started, the items run in this process on ``threads`` Python threads
(only their numpy parts overlap): a daemonic process may not have children (the GUI's
reconstruction process, a Dask worker), and a system without POSIX semaphores or ``fork``
cannot build the pool. Nothing else changes. Forking is safe here because the worker only runs
numpy, SciPy and small_gicp on the data it is sent (never an OpenMP library the parent may have
used on several threads, such as pykdtree's), and leaves by ``os._exit`` (multiprocessing's
fork children do), never through this process's exit handlers.
"""

from __future__ import annotations

import logging
import multiprocessing
import warnings
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from types import TracebackType
from typing import TypeVar

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")


def can_fork_a_worker() -> bool:
    """Whether this process may start a forked worker: not a daemonic process (whose children
    multiprocessing refuses) and a platform with the ``fork`` start method."""
    daemon = bool(multiprocessing.current_process().daemon)
    return not daemon and "fork" in multiprocessing.get_all_start_methods()


class ForkedMap:
    """Runs a function over items, results in order, on this process and (``threads`` >= 2)
    one forked worker. Use as a context manager; :attr:`worker_threads` is the OpenMP thread
    count each item should use (1 when two processes share the cores)."""

    def __init__(self, threads: int, fork: Callable[[], bool] = can_fork_a_worker) -> None:
        self._threads = threads
        self._worker: ProcessPoolExecutor | None = None
        self._local: Executor | None = None
        if threads >= 2 and fork():
            self._worker = _forked_worker()
        if self._worker is None and threads >= 2:
            self._local = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="pairs")

    @property
    def forked(self) -> bool:
        """Whether a worker process shares the pairs."""
        return self._worker is not None

    @property
    def worker_pid(self) -> int | None:
        """The worker process's id, when there is one."""
        if self._worker is None:
            return None
        return next(iter(self._worker._processes))  # the pool's one process, started at once

    @property
    def worker_threads(self) -> int:
        """OpenMP threads per pair: 1 beside a worker process, else ``threads``."""
        return 1 if self._worker is not None else self._threads

    def __enter__(self) -> ForkedMap:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Stop the worker (pairs not started are dropped) and the threads."""
        if self._worker is not None:
            self._worker.shutdown(wait=True, cancel_futures=True)
            self._worker = None
        if self._local is not None:
            self._local.shutdown(wait=True, cancel_futures=True)
            self._local = None

    def map(self, function: Callable[[T], R], items: Iterable[T]) -> Iterator[R]:
        """``function`` of each item, in order. With a worker, ``function`` and the items must
        pickle (a module-level function, plain data). Closing the iterator early drops the
        items not started."""
        items = list(items)
        if self._worker is None or len(items) < 2:
            mapped = self._local.map(function, items) if self._local else map(function, items)
            yield from mapped
            return
        yield from _shared(self._worker, function, items)


def _forked_worker() -> ProcessPoolExecutor | None:
    """A one-process pool forked now, or ``None`` (logged) where the system refuses one."""
    try:
        with warnings.catch_warnings():
            # Python 3.12+ warns that forking a multi-threaded process may deadlock the child
            # in a lock another thread held; the worker takes no such lock (module docstring)
            warnings.simplefilter("ignore", DeprecationWarning)
            pool = ProcessPoolExecutor(
                max_workers=1, mp_context=multiprocessing.get_context("fork")
            )
            pool.submit(int).result()  # fork now, not in the middle of the first pair
    except Exception as error:  # no semaphores (/dev/shm), no fork, a resource limit
        log.info("work of a stage kept in one process: no worker could be started (%s)", error)
        return None
    return pool


def _shared(worker: ProcessPoolExecutor, function: Callable[[T], R], items: list[T]) -> Iterator[R]:
    """The worker takes items from the front (its queue), this process from the back: an item
    still queued for the worker when this process reaches it is taken back (cancelled) and run
    here. Results are yielded in order as they are known. Should the worker die, what it had
    not returned runs here."""
    try:
        futures: list[Future[R]] = [worker.submit(function, item) for item in items]
    except BrokenProcessPool:  # the worker had died before these pairs
        log.warning("the worker process had ended: its items go on here")
        yield from map(function, items)
        return
    here: dict[int, R] = {}
    back = len(items) - 1
    try:
        for i, future in enumerate(futures):
            while back > i and not future.done():
                if futures[back].cancel():
                    here[back] = function(items[back])
                back -= 1
            if i in here:
                yield here.pop(i)
            elif future.cancel():
                yield function(items[i])
            else:
                try:
                    result = future.result()
                except BrokenProcessPool:  # the worker died (killed, out of memory): go on here
                    log.warning("the worker process ended: its items go on here")
                    result = function(items[i])
                yield result
    finally:
        for future in futures:
            future.cancel()
