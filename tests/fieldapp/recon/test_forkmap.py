"""The pairs shared by this process and a forked worker: results in order, the same as one
process's, and the work goes on here when no worker can be started or the worker dies."""

from __future__ import annotations

import os
import signal

from fieldapp.recon.forkmap import ForkedMap


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def test_results_come_in_order_from_this_process_and_the_worker() -> None:
    with ForkedMap(2) as runner:
        assert runner.forked and runner.worker_threads == 1
        worker = runner.worker_pid
        results = list(runner.map(_square_and_pid, range(40)))
    assert [value for value, _ in results] == [x * x for x in range(40)]
    assert {pid for _, pid in results} <= {os.getpid(), worker}


def test_one_thread_runs_every_pair_here() -> None:
    with ForkedMap(1) as runner:
        assert not runner.forked and runner.worker_threads == 1
        results = list(runner.map(_square_and_pid, range(5)))
    assert results == [(x * x, os.getpid()) for x in range(5)]


def test_a_process_that_may_not_fork_uses_its_threads() -> None:
    """A daemonic process (the GUI's reconstruction process, a Dask worker) has no worker:
    the pairs run here, each with the thread count asked for."""
    with ForkedMap(2, fork=lambda: False) as runner:
        assert not runner.forked and runner.worker_threads == 2
        results = list(runner.map(_square_and_pid, range(5)))
    assert results == [(x * x, os.getpid()) for x in range(5)]


def test_the_pairs_go_on_here_when_the_worker_dies() -> None:
    with ForkedMap(2) as runner:
        pid = runner.worker_pid
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        results = list(runner.map(_square_and_pid, range(6)))
    assert results == [(x * x, os.getpid()) for x in range(6)]


def test_closing_the_results_early_drops_the_pairs_not_started() -> None:
    with ForkedMap(2) as runner:
        results = runner.map(_square_and_pid, range(30))
        assert next(results)[0] == 0
        results.close()
        assert list(runner.map(_square_and_pid, range(3)))[2][0] == 4  # still usable
