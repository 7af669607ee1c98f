"""Items shared by this process and a forked worker: results in order, the same as one
process's, and the work goes on here when no worker can be started or the worker dies."""

from __future__ import annotations

import itertools
import multiprocessing
import os
import signal
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from fieldapp.recon.forkmap import ForkedMap, _Worker, largest_at_the_ends


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def _refuse_zero(x: int) -> int:
    if x == 0:
        raise ValueError(f"zero refused in process {os.getpid()}")
    return x


def test_results_come_in_order_from_this_process_and_the_worker() -> None:
    with ForkedMap(2) as runner:
        assert runner.forked and runner.worker_threads == 1
        worker = runner.worker_pid
        results = list(runner.map(_square_and_pid, range(40)))
    assert [value for value, _ in results] == [x * x for x in range(40)]
    assert results[0][1] == worker  # the worker takes the first item before anything else
    assert {pid for _, pid in results} <= {os.getpid(), worker}


def _done_here_or_wait_for_two_there(job: tuple[str, int, int]) -> tuple[int, bool]:
    """In the worker: item ``x`` marked done in ``folder``. Here: waits until the worker has
    done two items (a hang guard of 60 s, not a speed check); whether it saw them."""
    folder, parent, x = job
    if os.getpid() != parent:
        Path(folder, str(x)).touch()
        return x, True
    deadline = time.monotonic() + 60.0
    while len(os.listdir(folder)) < 2 and time.monotonic() < deadline:
        time.sleep(0.001)
    return x, len(os.listdir(folder)) >= 2


def test_the_worker_has_its_next_item_before_it_finishes_one(tmp_path: Path) -> None:
    """This process looks at the worker only between its own items: the worker holds the next
    one queued, so it goes on while this process is busy (given one at a time, it waited for
    the end of this process's item, here for ever)."""
    with ForkedMap(2) as runner:
        results = list(
            runner.map(
                _done_here_or_wait_for_two_there,
                [(str(tmp_path), os.getpid(), x) for x in range(4)],
            )
        )
    assert results == [(x, True) for x in range(4)]


def test_one_thread_runs_every_pair_here() -> None:
    with ForkedMap(1) as runner:
        assert not runner.forked and runner.worker_threads == 1
        results = list(runner.map(_square_and_pid, range(5)))
    assert results == [(x * x, os.getpid()) for x in range(5)]


def _forked_in(queue: Any) -> None:
    with ForkedMap(2) as runner:
        results = list(runner.map(_square_and_pid, range(6)))
        queue.put((runner.forked, [value for value, _ in results]))


def test_a_daemonic_process_gets_a_worker_too() -> None:
    """The GUI reconstructs in a daemonic multiprocessing child, which that module forbids
    children: the worker is forked without it."""
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_forked_in, args=(queue,), daemon=True)
    child.start()
    try:
        forked, values = queue.get(timeout=120)  # a hang guard, not a speed check
    finally:
        child.join(60)
    assert forked and values == [x * x for x in range(6)]
    assert child.exitcode == 0


def test_a_process_that_cannot_fork_uses_its_threads() -> None:
    """Where no worker can be forked the items run here, each with the thread count asked
    for."""
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


def _hang_in_the_worker(parent_and_x: tuple[int, int]) -> tuple[int, int]:
    parent, x = parent_and_x
    if os.getpid() != parent:
        threading.Event().wait()  # a lock that is never released
    return x * x, os.getpid()


def test_a_worker_that_hangs_is_stopped_and_its_items_go_on_here() -> None:
    with ForkedMap(2) as runner:
        pid = runner.worker_pid
        assert pid is not None
        ticks = itertools.count()
        runner.clock = lambda: 10.0 * next(ticks)  # 10 s pass at every look at the clock
        items = [(os.getpid(), x) for x in range(6)]
        results = list(runner.map(_hang_in_the_worker, items))
        assert not runner._worker.alive  # type: ignore[union-attr]
        later = list(runner.map(_square_and_pid, range(3)))  # the stage's later items: here
        assert later == [(x * x, os.getpid()) for x in range(3)]
    assert results == [(x * x, os.getpid()) for x in range(6)]
    with pytest.raises(ChildProcessError):  # killed and reaped
        os.waitpid(pid, os.WNOHANG)


def test_closing_the_results_early_drops_the_pairs_not_started() -> None:
    with ForkedMap(2) as runner:
        results = runner.map(_square_and_pid, range(30))
        assert next(results)[0] == 0
        results.close()
        assert list(runner.map(_square_and_pid, range(3)))[2][0] == 4  # still usable


def test_an_error_in_the_worker_is_raised_here() -> None:
    with ForkedMap(2) as runner:
        worker = runner.worker_pid
        with pytest.raises(ValueError, match=f"zero refused in process {worker}"):
            list(runner.map(_refuse_zero, range(5)))
        assert list(runner.map(_refuse_zero, range(1, 4))) == [1, 2, 3]  # still usable


def test_an_answer_no_longer_wanted_is_dropped() -> None:
    """A map closed while the worker held an item leaves its answer in the pipe: the next
    item's answer is the one received."""
    worker = _Worker.start()
    assert worker is not None
    try:
        worker.send(_square_and_pid, 3)
        wanted = worker.send(_square_and_pid, 4)
        assert worker.receive(wanted, 60.0)[0] == 16
    finally:
        worker.stop()


def _sleep(seconds: float) -> float:
    import time

    time.sleep(seconds)
    return seconds


def test_closing_waits_for_the_worker_to_exit_not_for_a_clock_tick(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An idle worker is reaped as soon as it has exited: closing wakes on its pipe's end, and
    sleeps (if at all) in steps far shorter than the old 50 ms tick it used to wait out twice
    per reconstruction."""
    import fieldapp.recon.forkmap as forkmap

    slept: list[float] = []
    real_sleep = forkmap.time.sleep
    monkeypatch.setattr(forkmap.time, "sleep", lambda s: (slept.append(s), real_sleep(s)))
    worker = _Worker.start()
    assert worker is not None
    token = worker.send(_square_and_pid, 2)
    assert worker.receive(token, 60.0)[0] == 4
    worker.stop()
    assert not worker._is_alive()
    assert all(s <= forkmap.EXIT_POLL_S for s in slept)


def test_a_worker_that_will_not_stop_is_killed_and_reaped() -> None:
    worker = _Worker.start()
    assert worker is not None
    worker.send(_sleep, 120.0)  # busy far beyond the wait
    worker.stop(wait_s=0.2)
    assert not worker._is_alive()
    with pytest.raises(ChildProcessError):  # reaped: no zombie left behind
        os.waitpid(worker.pid, os.WNOHANG)


def test_the_costliest_items_go_to_the_ends_and_the_cheapest_meet_in_the_middle() -> None:
    assert largest_at_the_ends([1.0, 5.0, 3.0, 4.0, 2.0]) == [1, 2, 0, 4, 3]
    assert largest_at_the_ends([2.0, 2.0, 2.0]) == [0, 2, 1]  # ties in index order
    assert largest_at_the_ends([]) == []


def test_with_costs_each_side_starts_on_the_costliest_and_results_stay_in_order() -> None:
    costs = [float(x % 7) for x in range(30)]
    with ForkedMap(2) as runner:
        worker = runner.worker_pid
        results = list(runner.map(_square_and_pid, range(30), costs))
    assert [value for value, _ in results] == [x * x for x in range(30)]
    assert results[largest_at_the_ends(costs)[0]][1] == worker  # the worker's first item
    with ForkedMap(1) as runner:  # one process: the costs change nothing
        assert list(runner.map(_square_and_pid, range(5), [5.0, 1, 2, 3, 4])) == [
            (x * x, os.getpid()) for x in range(5)
        ]
