"""ui.workers: a job's results, errors and progress arrive on the GUI thread in order, a
cancelled generator is closed on the job's own thread, and nothing a job was given outlives it
(superqt's workers, which these replaced, kept about a third of theirs, and let their signals
object die on a pool thread)."""

from __future__ import annotations

import gc
import threading
import weakref
from collections.abc import Generator
from typing import Any

import pytest

from ui.workers import Job, WorkerSet

from .conftest import WaitUntil

pytestmark = pytest.mark.usefixtures("no_leaks")


def on_gui_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def test_progress_then_the_result_then_finished_all_on_the_gui_thread(
    wait_until: WaitUntil,
) -> None:
    seen: list[tuple[str, Any, bool]] = []
    ran_on: list[bool] = []

    def steps() -> Generator[int, None, str]:
        ran_on.append(on_gui_thread())
        yield from range(5)
        return "done"

    def note(kind: str) -> Any:
        return lambda value=None: seen.append((kind, value, on_gui_thread()))

    jobs: list[Job] = []

    def finished() -> None:
        seen.append(("finished", jobs[0].running, on_gui_thread()))

    jobs.append(
        Job(steps, on_progress=note("progress"), on_done=note("done"), on_finished=finished)
    )
    job = jobs[0]
    job.start()
    assert wait_until(lambda: not job.running and seen and seen[-1][0] == "finished")
    assert ran_on == [False]
    assert [(kind, value) for kind, value, _ in seen] == [
        *(("progress", step) for step in range(5)),
        ("done", "done"),
        ("finished", False),
    ]
    assert all(gui for _, _, gui in seen)


def test_an_error_goes_to_on_error_and_the_job_still_finishes(wait_until: WaitUntil) -> None:
    errors: list[BaseException] = []
    finished: list[bool] = []

    def fail() -> None:
        raise RuntimeError("the disk is full")

    Job(fail, on_error=errors.append, on_finished=lambda: finished.append(True)).start()
    assert wait_until(lambda: bool(finished))
    assert [str(e) for e in errors] == ["the disk is full"]


def test_cancel_closes_the_generator_on_its_own_thread_before_the_next_step(
    wait_until: WaitUntil,
) -> None:
    release = threading.Event()
    closed_on_gui: list[bool] = []
    outcome: list[str] = []
    steps_taken: list[int] = []

    def steps() -> Generator[int, None, None]:
        try:
            for step in range(100):
                steps_taken.append(step)
                yield step
                release.wait(30)
        finally:
            closed_on_gui.append(on_gui_thread())

    job = Job(
        steps,
        on_done=lambda _: outcome.append("done"),
        on_cancelled=lambda: outcome.append("cancelled"),
    )
    job.start()
    assert wait_until(lambda: bool(steps_taken))
    job.cancel()
    release.set()
    assert wait_until(lambda: not job.running)
    assert outcome == ["cancelled"] and closed_on_gui == [False]
    assert len(steps_taken) < 100


def test_a_worker_set_is_idle_when_its_callback_runs(wait_until: WaitUntil) -> None:
    workers = WorkerSet()
    busy_in_callback: list[bool] = []
    workers.run(lambda: 1, lambda _: busy_in_callback.append(workers.busy))
    assert workers.busy
    assert workers.wait(30.0)
    assert busy_in_callback == [False]


def test_nothing_a_job_was_given_outlives_it(wait_until: WaitUntil) -> None:
    class Frame:  # what a live view hands its detection jobs
        pass

    workers = WorkerSet()
    alive: list[weakref.ref[Frame]] = []
    results: list[int] = []
    for _ in range(50):
        frame = Frame()
        alive.append(weakref.ref(frame))
        workers.run(lambda frame=frame: id(frame), results.append)
        del frame
    assert workers.wait(60.0)
    assert wait_until(lambda: len(results) == 50)
    gc.collect()
    assert sum(ref() is not None for ref in alive) == 0
