"""Reading a station's frames (issue 22): on several threads, the same scan as on one."""

from __future__ import annotations

import shutil
import threading
from pathlib import Path

import numpy as np
import pytest

from fieldapp.io.session import Capture, CaptureImages, Session, load_session
from fieldapp.recon import scans
from fieldapp.recon.backproject import ray_table
from fieldapp.recon.depth_only import read_scan_capture
from fieldapp.recon.exg import BY_COLOUR, excess_green, otsu_threshold
from fieldapp.recon.scans import StationScan, captures_by_station, read_station
from fieldapp.recon.settings import ReconstructionSettings


def _read(session: Session, station: int, threads: int) -> tuple[StationScan | None, list[str]]:
    settings = ReconstructionSettings()
    return read_station(
        session,
        station,
        captures_by_station(session)[station],
        settings.crop,
        settings.filters.exg_threshold,
        settings.ground.soil_pixel_stride,
        ray_table(session.calibration.depth_camera.intrinsics()),
        threads,
    )


def _assert_same_scan(a: StationScan, b: StationScan) -> None:
    for cloud in ("green", "soil"):
        np.testing.assert_array_equal(getattr(a, cloud).points, getattr(b, cloud).points)
        np.testing.assert_array_equal(getattr(a, cloud).colors, getattr(b, cloud).colors)
    assert (a.station, a.views, a.exg_threshold) == (b.station, b.views, b.exg_threshold)
    assert (a.measured_pixels, a.separation) == (b.measured_pixels, b.separation)


def test_two_threads_read_a_station_into_the_same_scan_as_one(small_session: Path) -> None:
    session = load_session(small_session)
    for station in (4, 5):
        one, warnings_one = _read(session, station, 1)
        two, warnings_two = _read(session, station, 2)
        assert one is not None and two is not None and warnings_one == warnings_two == []
        assert len(one.green) > 0 and len(one.soil) > 0
        _assert_same_scan(one, two)


def test_an_unreadable_frame_is_skipped_with_a_warning_on_any_thread_count(
    small_session: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "damaged"
    shutil.copytree(small_session, folder)
    (folder / "frames" / "s05" / "v0" / "color.png").write_bytes(b"not a png")
    session = load_session(folder)
    results = [_read(session, 5, threads) for threads in (1, 2)]
    for scan, warnings in results:
        assert scan is not None and scan.views == [1]
        assert len(warnings) == 1 and warnings[0].startswith("station 5 view 0 skipped: ")
        assert "color.png" in warnings[0]
    _assert_same_scan(results[0][0], results[1][0])  # type: ignore[arg-type]


def test_two_threads_read_two_frames_at_once(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each frame's reading waits until another is being read: only possible when two threads
    read frames together (one thread would wait for ever: the barrier times out)."""
    together = threading.Barrier(2, timeout=60)
    read = scans.read_scan_capture

    def read_with_another(session: Session, capture: Capture) -> CaptureImages:
        together.wait()
        return read(session, capture)

    monkeypatch.setattr(scans, "read_scan_capture", read_with_another)
    scan, warnings = _read(load_session(small_session), 4, 2)
    assert scan is not None and scan.views == [0, 1] and warnings == []


def test_the_frame_threads_give_back_the_memory_they_freed(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Once per station read on several threads (glibc keeps a thread's freed memory in its
    own arena), never on one thread; and it runs where it is real."""
    calls: list[int] = []
    real = scans.return_freed_memory
    monkeypatch.setattr(scans, "return_freed_memory", lambda: calls.append(1) or real())
    session = load_session(small_session)
    _read(session, 4, 1)
    assert calls == []
    _read(session, 4, 2)
    _read(session, 5, 2)
    assert calls == [1, 1]


def test_the_station_threshold_is_otsus_over_its_measured_pixels_excess_green(
    small_session: Path,
) -> None:
    """The threshold found from the tally of colour keys (issue 22) is, bit for bit, Otsu's
    threshold over every measured pixel's ExG, as computed before the tally."""
    session = load_session(small_session)
    for station in (4, 5):
        scan, _ = _read(session, station, 1)
        assert scan is not None and scan.separation == BY_COLOUR
        frames = [read_scan_capture(session, c) for c in captures_by_station(session)[station]]
        exg = np.concatenate([excess_green(f.color[np.isfinite(f.depth_m)]) for f in frames])
        assert scan.measured_pixels == len(exg)
        assert scan.exg_threshold == otsu_threshold(exg)
