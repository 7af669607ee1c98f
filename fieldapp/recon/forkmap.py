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

Where no worker can be started (a system without ``fork``, a process limit), the items run in
this process on ``threads`` Python threads (only their numpy parts overlap). Nothing else
changes. The worker is forked with ``os.fork``, not as a ``multiprocessing.Process``, so the
GUI's reconstruction process (a daemonic ``multiprocessing`` child, which that module forbids
children) gets one too; it never outlives this process for long: it ends when its pipe closes.
Forking is safe here because the worker only runs numpy, SciPy and small_gicp on the data it is
sent (never an OpenMP library the parent may have used on several threads, such as pykdtree's),
and leaves by ``os._exit``, never through this process's exit handlers.

The worker is a plain process on a pipe, running its items in turn, not a
``ProcessPoolExecutor``: that pool's manager thread fails on Python 3.11 when a worker dies while
an item it had queued was taken back (``InvalidStateError`` on a cancelled future), and could
leave the other items never finished. Here a worker that dies (killed, out of memory) is noticed
on the pipe and its items run in this process like the rest.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import queue
import signal
import threading
import time
import traceback
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor, ThreadPoolExecutor
from multiprocessing.connection import Connection
from types import TracebackType
from typing import Any, TypeVar

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")

QUEUED = 1
"""Items the worker holds queued behind the one it runs, so it never waits for this process."""
POLL_S = 0.05
"""How often the wait for the worker's last item checks that the worker is alive."""
STOP_WAIT_S = 5.0
"""How long closing waits for the worker to finish its item before killing it."""
EXIT_POLL_S = 0.001
"""How often closing checks that a worker whose pipe has closed has been reaped."""
WORKER_STALL_S = 120.0
"""How long this process, with nothing left to run itself, waits for the worker's item before
it takes the worker for hung (a lock some thread held when it was forked) and kills it: the
item then runs here, and so does every later item of the stage. A registration pair or a
plant's organs take well under a second on the plots measured, a 9 x 9 plot's pairs a few."""


def can_fork_a_worker() -> bool:
    """Whether this platform can fork (POSIX)."""
    return hasattr(os, "fork")


class ForkedMap:
    """Runs a function over items, results in order, on this process and (``threads`` >= 2)
    one forked worker. Use as a context manager; :attr:`worker_threads` is the OpenMP thread
    count each item should use (1 when two processes share the cores)."""

    def __init__(self, threads: int, fork: Callable[[], bool] = can_fork_a_worker) -> None:
        self._threads = threads
        self._worker: _Worker | None = None
        self._local: Executor | None = None
        self.clock: Callable[[], float] = time.monotonic
        self.stall_s = WORKER_STALL_S
        if threads >= 2 and fork():
            self._worker = _Worker.start()
        if self._worker is None and threads >= 2:
            self._local = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="forkmap")

    @property
    def forked(self) -> bool:
        """Whether a worker process shares the items."""
        return self._worker is not None

    @property
    def worker_pid(self) -> int | None:
        """The worker process's id, when there is one."""
        return None if self._worker is None else self._worker.pid

    @property
    def worker_threads(self) -> int:
        """OpenMP threads per item: 1 beside a worker process, else ``threads``."""
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
        """Stop the worker (after its item, or killed) and the threads."""
        if self._worker is not None:
            self._worker.stop()
            self._worker = None
        if self._local is not None:
            self._local.shutdown(wait=True, cancel_futures=True)
            self._local = None

    def map(
        self,
        function: Callable[[T], R],
        items: Iterable[T],
        costs: Sequence[float] | None = None,
    ) -> Iterator[R]:
        """``function`` of each item, in order. With a worker, ``function`` and the items must
        pickle (a module-level function, plain data). Closing the iterator early leaves the
        items not started undone. ``costs``: each item's expected cost (any unit); with a
        worker, each side then starts on the largest and the two meet on the smallest
        (:func:`largest_at_the_ends`), so neither waits long for the other's last item."""
        items = list(items)
        if self._worker is not None and len(items) >= 2:
            order = list(range(len(items))) if costs is None else largest_at_the_ends(costs)
            yield from self._shared(function, items, order)
            return
        yield from (self._local.map(function, items) if self._local else map(function, items))

    def _shared(self, function: Callable[[T], R], items: list[T], order: list[int]) -> Iterator[R]:
        """The worker takes items from the front of ``order``, this process from the back, until
        they meet; results are yielded in the items' order as soon as they are known.

        The worker holds its item and, while this process has items of its own left, the next
        one queued behind it (:data:`QUEUED`): this process looks at the worker only between
        its own items, so a worker given one item at a time sat idle from the end of its item
        to the end of this process's (seed 1's registration: 7 of its 20 pairs, idle 40 % of
        the stage)."""
        worker = self._worker
        assert worker is not None
        done: dict[int, R] = {}
        front, back = 0, len(items) - 1
        held: deque[tuple[int, int]] = deque()  # the worker's items: (token, index), oldest first
        since = self.clock()  # the worker's last answer, or the item sent to it idle
        for i in range(len(items)):
            while i not in done:
                while worker.alive and front <= back and len(held) <= QUEUED:
                    if held and back == front:  # the last item left: this process's own
                        break
                    if not held:
                        since = self.clock()
                    held.append((worker.send(function, items[order[front]]), order[front]))
                    front += 1
                if held and (front > back or worker.ready()):
                    token, index = held[0]
                    outcome = worker.receive(token, POLL_S if front > back else 0.0)
                    if outcome is _PENDING and self.clock() - since > self.stall_s:
                        log.warning(
                            "the worker process (pid %d) has held one item for %.0f s: "
                            "stopped; its items go on here",
                            worker.pid,
                            self.stall_s,
                        )
                        worker.kill()
                        outcome = _DIED
                    if outcome is _PENDING:
                        continue
                    if outcome is _DIED:
                        log.warning("the worker process ended: its items go on here")
                        for _, index in held:
                            done[index] = function(items[index])
                        held.clear()
                    else:
                        done[index] = outcome
                        held.popleft()
                        since = self.clock()
                elif front <= back:
                    done[order[back]], back = function(items[order[back]]), back - 1
            yield done.pop(i)


def largest_at_the_ends(costs: Sequence[float]) -> list[int]:
    """An order of the items (indices) with the costliest at both ends and the cheapest in the
    middle, alternately front and back from the largest down (ties in index order): two
    processes taking items from the two ends then meet on cheap items."""
    by_cost = sorted(range(len(costs)), key=lambda i: (-costs[i], i))
    front = by_cost[0::2]
    back = by_cost[1::2]
    return front + back[::-1]


_PENDING = object()
_DIED = object()


class _Worker:
    """A forked process running ``function(item)`` for this process, one at a time in the
    order sent: sent as ``(token, function, item)``, answered ``(token, "ok", result)`` or
    ``(token, "error", exception)``. The token tells the answer wanted from that of an item
    whose results were no longer wanted (a map closed early), which is dropped."""

    def __init__(self, pid: int, connection: Connection) -> None:
        self._pid = pid
        self._connection = connection
        self._token = 0
        self._ended = False
        self.alive = True

    @classmethod
    def start(cls) -> _Worker | None:
        """A worker forked now, or ``None`` (logged) where the system refuses one."""
        try:
            here, there = multiprocessing.Pipe(duplex=True)
            with warnings.catch_warnings():
                # Python 3.12+ warns that forking a multi-threaded process may deadlock the
                # child in a lock another thread held; the worker takes none (module docstring)
                warnings.simplefilter("ignore", DeprecationWarning)
                pid = os.fork()
        except Exception as error:  # no fork, a process limit, no file descriptors
            log.info("a stage's work kept in one process: no worker could be started (%s)", error)
            return None
        if pid == 0:  # the worker: serve, then leave without this process's exit handlers
            code = 1
            try:
                here.close()
                _serve(there)
                code = 0
            finally:
                os._exit(code)
        there.close()
        return cls(pid, here)

    @property
    def pid(self) -> int:
        return self._pid

    def _is_alive(self) -> bool:
        """Whether the worker runs (reaping it when it has ended)."""
        if self._ended:
            return False
        try:
            pid, _ = os.waitpid(self._pid, os.WNOHANG)
        except ChildProcessError:
            pid = self._pid
        self._ended = pid == self._pid
        return not self._ended

    def send(self, function: Callable[[Any], Any], item: Any) -> int:
        """Queue ``function(item)`` on the worker; its token, for :meth:`receive`."""
        self._token += 1
        with contextlib.suppress(OSError, EOFError):  # the worker has gone: receive() says so
            self._connection.send((self._token, function, item))
        return self._token

    def ready(self) -> bool:
        """Whether an answer (or the end of the pipe) is waiting."""
        try:
            return bool(self._connection.poll(0))
        except (OSError, EOFError):
            return True

    def receive(self, token: int, wait_s: float) -> Any:
        """The result of the item sent as ``token`` (the answers of items sent before it, no
        longer wanted, are dropped), ``_PENDING`` if none came within ``wait_s``, or
        ``_DIED`` when the worker ended; raises the item's own exception."""
        try:
            while True:
                if not self._connection.poll(wait_s):
                    if self._is_alive():
                        return _PENDING
                    raise EOFError
                answered, kind, payload = self._connection.recv()
                if answered == token:
                    break
        except (OSError, EOFError):
            self.alive = False
            return _DIED
        if kind == "error":
            raise payload
        return payload

    def kill(self) -> None:
        """Kill the worker now and reap it (it holds nothing to clean up)."""
        with contextlib.suppress(ProcessLookupError):
            os.kill(self._pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(self._pid, 0)
        self._ended, self.alive = True, False

    def stop(self, wait_s: float = STOP_WAIT_S) -> None:
        """Ask the worker to end after its item; kill it if it has not within ``wait_s`` (it
        holds nothing to clean up); reap it either way. The wait ends when the worker's end of
        the pipe closes (it has exited), not at the next tick of a clock: a stage's last
        milliseconds are everybody's wall time."""
        with contextlib.suppress(OSError, EOFError):
            self._connection.send(None)
        deadline = time.monotonic() + wait_s
        try:  # an answer no longer wanted may come first; EOFError once the worker has exited
            while self._connection.poll(max(deadline - time.monotonic(), 0.0)):
                self._connection.recv()
        except (OSError, EOFError):
            pass
        self._connection.close()
        while self._is_alive() and time.monotonic() < deadline:  # closed its pipe: exiting
            time.sleep(EXIT_POLL_S)
        if self._is_alive():
            self.kill()


def _serve(connection: Connection) -> None:
    """The worker's loop: run each ``(token, function, item)`` received, in order, until
    ``None``. A thread reads the items as they come, so this process's send of an item (most
    are larger than the pipe's buffer) never waits for the worker's item before it; the items
    still queued at ``None`` are dropped."""
    jobs: queue.SimpleQueue[Any] = queue.SimpleQueue()
    stopping = threading.Event()

    def read() -> None:
        with contextlib.suppress(EOFError, OSError):
            while (job := connection.recv()) is not None:
                jobs.put(job)
        stopping.set()
        jobs.put(None)

    threading.Thread(target=read, name="forkmap-reader", daemon=True).start()
    while (job := jobs.get()) is not None and not stopping.is_set():
        token, function, item = job
        try:
            answer: tuple[int, str, Any] = (token, "ok", function(item))
        except Exception as error:
            answer = (token, "error", error)
        try:
            connection.send(answer)
        except Exception:  # an answer that does not pickle
            text = "".join(traceback.format_exception(answer[2])) if answer[1] == "error" else ""
            problem = RuntimeError(f"the worker's answer did not pickle {text}")
            connection.send((token, "error", problem))
