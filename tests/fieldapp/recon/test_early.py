"""Stations read by a process forked at start-up (issue 22): the same scans and warnings as
read here, a reader that dies or fails has its stations read here, errors raised as before."""

from __future__ import annotations

import itertools
import os
import shutil
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from fieldapp.io.session import Session, load_session
from fieldapp.recon import early
from fieldapp.recon.backproject import ray_table
from fieldapp.recon.early import EarlyStations, StationRead, read_arguments, start_reading
from fieldapp.recon.scans import StationScan, captures_by_station, read_station
from fieldapp.recon.settings import CropSettings, ReconstructionSettings

from .test_scans import _assert_same_scan

SETTINGS = ReconstructionSettings()


def _here(session: Session) -> dict[int, StationRead]:
    """Every station read in this process, as the pipeline does without a reader."""
    rays = ray_table(session.calibration.depth_camera.intrinsics())
    a = read_arguments(SETTINGS, session.calibration)
    return {
        station: read_station(
            session, station, captures, a.crop, a.exg_threshold, a.soil_pixel_stride, rays
        )
        for station, captures in captures_by_station(session).items()
    }


def _read_all(reader: EarlyStations) -> tuple[dict[int, StationRead], list[int]]:
    """The reader's result, and the stations in the order they were reported done."""
    steps, reported = reader.read(threads=2), []
    while True:
        try:
            reported.append(next(steps))
        except StopIteration as done:
            return done.value, reported


def _wait_for_the_reader_to_take_the_first(reader: EarlyStations) -> None:
    """No timing: the reader takes station 4 before this process takes any (a hang is left to
    pytest-timeout)."""
    while reader._claims.taken_from_front() < 1:
        os.sched_yield()


def _assert_same(a: dict[int, StationRead], b: dict[int, StationRead]) -> None:
    assert list(a) == list(b)
    for station in a:
        (scan_a, warnings_a), (scan_b, warnings_b) = a[station], b[station]
        assert warnings_a == warnings_b
        assert isinstance(scan_a, StationScan) and isinstance(scan_b, StationScan)
        _assert_same_scan(scan_a, scan_b)


def test_the_reader_and_this_process_share_the_stations_into_the_same_scans(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session = load_session(small_session)
    reader = start_reading(session, SETTINGS)
    assert reader is not None and reader.serves(
        session, read_arguments(SETTINGS, session.calibration)
    )
    _wait_for_the_reader_to_take_the_first(reader)
    here: list[int] = []

    def watched(s: Session, station: int, *args: object) -> StationRead:
        here.append(station)  # the reader, forked before, is not watched
        return read_station(s, station, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(early, "read_station", watched)
    read, reported = _read_all(reader)
    assert here == [5]  # station 4 came from the reader
    assert sorted(reported) == [4, 5] and reader.pid is None  # reaped
    _assert_same(read, _here(session))


def _reader_that(
    fails: Callable[[], object], session: Session, monkeypatch: pytest.MonkeyPatch
) -> EarlyStations:
    """A reader of ``session`` whose reading calls ``fails`` (in the reader only), started
    and holding its first station."""
    parent = os.getpid()

    def read_in_the_reader(s: Session, station: int, *args: object) -> StationRead:
        if os.getpid() != parent:
            fails()
        return read_station(s, station, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(early, "read_station", read_in_the_reader)
    reader = start_reading(session, SETTINGS)
    assert reader is not None
    _wait_for_the_reader_to_take_the_first(reader)
    return reader


def test_a_reader_that_dies_has_its_stations_read_here(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session = load_session(small_session)
    # killed mid-read: no answer, no clean exit
    reader = _reader_that(lambda: os._exit(3), session, monkeypatch)
    read, reported = _read_all(reader)
    assert sorted(reported) == [4, 5]
    _assert_same(read, _here(session))


def test_a_reader_that_hangs_is_stopped_and_its_stations_read_here(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session = load_session(small_session)
    # a lock that is never released
    reader = _reader_that(threading.Event().wait, session, monkeypatch)
    ticks = itertools.count()
    reader.clock = lambda: 10.0 * next(ticks)  # 10 s pass at every look at the clock
    pid = reader.pid
    read, reported = _read_all(reader)
    assert sorted(reported) == [4, 5] and reader.pid is None
    _assert_same(read, _here(session))
    with pytest.raises(ChildProcessError):  # killed and reaped
        os.waitpid(pid, os.WNOHANG)  # type: ignore[arg-type]


def test_a_corrupt_frame_read_by_the_reader_is_reported_as_here(
    small_session: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "damaged"
    shutil.copytree(small_session, folder)
    (folder / "frames" / "s04" / "v0" / "color.png").write_bytes(b"not a png")
    session = load_session(folder)
    reader = start_reading(session, SETTINGS)
    assert reader is not None
    _wait_for_the_reader_to_take_the_first(reader)  # station 4, the damaged one
    read, _ = _read_all(reader)
    _assert_same(read, _here(session))
    scan, warnings = read[4]
    assert scan is not None and scan.views == [1]
    assert len(warnings) == 1 and warnings[0].startswith("station 4 view 0 skipped: ")
    assert "color.png" in warnings[0]


def test_an_error_is_raised_here_for_the_first_station_that_raises(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def fails(session: Session, station: int, *args: object) -> StationRead:
        raise ValueError(f"station {station} cannot be read (in {os.getpid()})")

    monkeypatch.setattr(early, "read_station", fails)
    reader = start_reading(load_session(small_session), SETTINGS)
    assert reader is not None
    with pytest.raises(ValueError, match=f"station 4 cannot be read \\(in {os.getpid()}\\)"):
        _read_all(reader)
    assert reader.pid is None


def test_no_reader_on_one_thread_or_without_fork(small_session: Path) -> None:
    session = load_session(small_session)
    arguments = read_arguments(SETTINGS, session.calibration)
    assert EarlyStations.start(session, arguments, threads=1) is None
    assert EarlyStations.start(session, arguments, threads=2, fork=lambda: False) is None


def test_a_reader_not_used_is_killed_and_reaped(small_session: Path) -> None:
    session = load_session(small_session)
    reader = start_reading(session, SETTINGS)
    assert reader is not None and reader.pid is not None
    pid, other = reader.pid, ReconstructionSettings(crop=CropSettings(radius_m=1.0))
    assert reader.serves(session, read_arguments(SETTINGS, session.calibration))
    assert not reader.serves(session, read_arguments(other, session.calibration))  # other settings
    assert not reader.serves(
        load_session(small_session), read_arguments(SETTINGS, session.calibration)
    )
    reader.close()
    assert reader.pid is None
    with pytest.raises(ChildProcessError):  # reaped: no zombie left
        os.waitpid(pid, os.WNOHANG)


def test_a_calibration_the_rays_cannot_come_from_starts_no_reader(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The pipeline raises it where it did before, after its own checks of the calibration."""

    def no_rays(*_: object) -> None:
        raise ValueError("no ray table")

    monkeypatch.setattr(early, "ray_table", no_rays)
    assert start_reading(load_session(small_session), SETTINGS) is None


def _putting(outbox: early.Outbox, message: bytes) -> threading.Thread:
    thread = threading.Thread(target=outbox.put, args=(message,), daemon=True)
    thread.start()
    return thread


def test_the_reader_reads_no_further_ahead_than_its_outbox_holds() -> None:
    """A depth-only station is 40-50 MB pickled: the reader queued every station of a plot
    while the pipeline imported. Now a message waits for room (one always fits when none
    waits), and room comes when a message has been sent."""
    outbox = early.Outbox(limit=10)
    outbox.put(b"x" * 25)  # larger than the limit, but nothing waits: queued at once
    second = _putting(outbox, b"y" * 4)
    second.join(timeout=0.2)
    assert second.is_alive()  # 25 + 4 bytes would exceed the limit
    assert outbox.get() == b"x" * 25
    outbox.sent(25)
    second.join(timeout=30.0)
    assert not second.is_alive() and outbox.get() == b"y" * 4
    outbox.put(b"z" * 5)  # 4 still being sent: 9 fit
    outbox.finish()
    assert outbox.get() == b"z" * 5 and outbox.get() is None


def test_a_reader_waiting_for_room_stops_when_the_pipeline_has_gone() -> None:
    outbox = early.Outbox(limit=10)
    outbox.put(b"x" * 8)
    waiting = _putting(outbox, b"y" * 8)
    outbox.close()  # the pipeline closed its end: the sender saw OSError
    waiting.join(timeout=30.0)
    assert not waiting.is_alive() and outbox.get() is None
