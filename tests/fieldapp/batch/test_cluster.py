"""Options of the cluster, Dask's logging kept quiet, the progress figures."""

from __future__ import annotations

import logging
import os
import platform
import resource

import pytest

from fieldapp.batch.cluster import (
    GlibcMallocThresholds,
    memory_limit_bytes,
    open_client,
    quiet_dask_logging,
)
from fieldapp.batch.runner import BatchStatus
from fieldapp.batch.task import BatchError
from fieldapp.cli.batch import format_duration, usable_cpus


@pytest.mark.parametrize(
    ("text", "expected"),
    [("auto", "auto"), ("AUTO", "auto"), ("4GiB", 4 * 2**30), ("500MB", 500 * 10**6), ("0", 0)],
)
def test_memory_limits(text, expected):
    assert memory_limit_bytes(text) == expected


@pytest.mark.parametrize("text", ["lots", "4 parsecs", "-1GB", ""])
def test_bad_memory_limits_name_the_option(text):
    with pytest.raises(BatchError, match="--memory-limit"):
        memory_limit_bytes(text)


def test_at_least_one_worker():
    with pytest.raises(BatchError, match="--workers: 0"), open_client(None, 0):
        pass


@pytest.mark.parametrize("address", ["nonsense", "foo://host:1", "tcp://127.0.0.1:1"])
def test_an_unreachable_scheduler_is_one_clear_error(address):
    with (
        pytest.raises(BatchError, match=f"--scheduler: cannot reach {address}"),
        open_client(address, 1, connect_timeout_s=0.5),
    ):
        pass


def test_dask_logs_are_errors_only_inside_and_as_before_after():
    logger = logging.getLogger("distributed")
    logger.setLevel(logging.DEBUG)
    try:
        with quiet_dask_logging():
            assert logger.level == logging.ERROR
            assert logging.getLogger("distributed.worker").getEffectiveLevel() == logging.ERROR
        assert logger.level == logging.DEBUG
    finally:
        logger.setLevel(logging.NOTSET)


def test_time_left_at_the_pace_so_far():
    assert BatchStatus(10, 0, 0, 2, 30.0).time_left_s is None
    assert BatchStatus(10, 3, 1, 2, 40.0).time_left_s == pytest.approx(60.0)
    assert BatchStatus(10, 9, 1, 0, 40.0).time_left_s == 0.0
    assert BatchStatus(10, 3, 1, 2, 40.0).finished == 4


@pytest.mark.parametrize(
    ("seconds", "text"), [(0.0, "0:00"), (75.4, "1:15"), (3725.0, "1:02:05"), (-3.0, "0:00")]
)
def test_durations(seconds, text):
    assert format_duration(seconds) == text


def test_default_workers_are_the_cpus_this_process_may_use():
    assert 1 <= usable_cpus() <= (os.cpu_count() or 1)
    if hasattr(os, "sched_getaffinity"):
        assert usable_cpus() == len(os.sched_getaffinity(0))


def _page_faults_per_large_array() -> float:
    """Minor page faults per 8 MiB array written and freed, over 20 arrays after a first one
    (which faults its 2048 pages in once, or 4 huge pages where numpy asks for them)."""
    import numpy as np

    first = np.ones(2**20)  # its pages are faulted in whatever the thresholds
    del first
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(20):
        block = np.ones(2**20)
        del block
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 20


def _pinned_by_dask() -> str | None:
    return os.environ.get("MALLOC_TRIM_THRESHOLD_")


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's malloc thresholds")
def test_workers_reuse_freed_large_blocks_instead_of_faulting_them_in_again():
    with open_client(None, 1, "1GiB") as client:
        (pinned,) = client.run(_pinned_by_dask).values()
        (faults,) = client.run(_page_faults_per_large_array).values()
    # Dask's nanny pins the thresholds; unrepaired, each array faults in anew (516 here).
    assert pinned is not None
    assert faults < 100


def test_the_thresholds_are_left_alone_when_nothing_pinned_them(monkeypatch):
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    monkeypatch.delenv("MALLOC_MMAP_THRESHOLD_", raising=False)
    assert GlibcMallocThresholds.apply() is False
