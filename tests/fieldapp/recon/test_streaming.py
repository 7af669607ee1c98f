"""Steps 3-4 for each station as soon as it is read: its green points (every point it measured
in a depth-only session) dropped then, the same levelling and filtering as all together."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fieldapp.io.session import Session, load_session
from fieldapp.recon import pipeline, progress, stages
from fieldapp.recon.backproject import ray_table
from fieldapp.recon.early import start_reading
from fieldapp.recon.progress import StageTimer
from fieldapp.recon.scans import StationScan, captures_by_station
from fieldapp.recon.settings import ReconstructionSettings

from .test_pipeline_stages import _same


def _scans(session: Session, settings: ReconstructionSettings) -> dict[int, StationScan]:
    rays = ray_table(session.calibration.depth_camera.intrinsics())
    read = {
        station: stages.station_scan(
            session,
            station,
            captures,
            rays,
            settings.crop,
            settings.filters.exg_threshold,
            settings.ground.soil_pixel_stride,
        )
        for station, captures in captures_by_station(session).items()
    }
    return {s: r.value for s, r in read.items() if r.value is not None}


def _all_together(
    session: Session,
    scans: dict[int, StationScan],
    reference: int,
    settings: ReconstructionSettings,
) -> tuple[stages.Staged[dict[int, np.ndarray]], dict[int, object]]:
    """Steps 3-4 as they ran before streaming: every station read first."""
    levelled = stages.level(
        stages.LocalScans(scans), session.calibration, reference, settings.ground
    )
    filtered = {
        s: stages.filter_plants(scan, levelled.value[s], settings.filters, settings.ground)
        for s, scan in scans.items()
    }
    return levelled, filtered


def _without_ground(session: Session) -> Session:
    """``session`` whose calibration has no ground transform: the reference's ground gives
    the field frame."""
    calibration = session.calibration.model_copy(update={"ground": None})
    return dataclasses.replace(session, calibration=calibration)


def _counting_filters(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    filtered: list[int] = []
    original = stages.filter_plants

    def counted(scan: StationScan, *args: object) -> object:
        filtered.append(scan.station)
        return original(scan, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(stages, "filter_plants", counted)
    return filtered


def test_stations_read_before_the_reference_wait_for_it_then_all_are_placed_alike(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session, settings = _without_ground(load_session(small_session)), ReconstructionSettings()
    assert session.calibration.stations is not None
    assert session.calibration.stations.reference == 5
    scans = _scans(session, settings)
    expected = _all_together(session, scans, 5, settings)
    filtered = _counting_filters(monkeypatch)
    stream = pipeline._Streaming(session, settings, StageTimer())
    kept = {4: stream.take(scans[4])}
    assert filtered == []  # the field frame comes from the reference's ground: not read yet
    kept[5] = stream.take(scans[5])
    assert filtered == [4, 5]
    assert all(len(scan.green) == 0 for scan in kept.values())  # dropped once placed
    assert all(_same(kept[s].soil, scans[s].soil) for s in kept)  # the anchor's ground
    levelled, placed = stream.placed(5, kept)
    assert filtered == [4, 5]  # nothing placed twice
    assert _same(levelled, expected[0]) and _same(placed, expected[1])


def test_with_a_ground_calibration_each_station_is_placed_as_it_is_read(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session, settings = load_session(small_session), ReconstructionSettings()
    assert session.calibration.ground is not None  # as the simulator writes it
    scans = _scans(session, settings)
    expected = _all_together(session, scans, 5, settings)
    filtered = _counting_filters(monkeypatch)
    stream = pipeline._Streaming(session, settings, StageTimer())
    kept = {4: stream.take(scans[4])}
    assert filtered == [4]
    kept[5] = stream.take(scans[5])
    assert filtered == [4, 5]
    levelled, placed = stream.placed(5, kept)
    assert _same(levelled, expected[0]) and _same(placed, expected[1])


def test_without_the_reference_the_anchoring_station_gives_the_field_frame_at_the_end(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session, settings = _without_ground(load_session(small_session)), ReconstructionSettings()
    scans = {4: _scans(session, settings)[4]}  # station 5, the reference, unusable
    expected = _all_together(session, scans, 4, settings)
    filtered = _counting_filters(monkeypatch)
    stream = pipeline._Streaming(session, settings, StageTimer())
    kept = {4: stream.take(scans[4])}
    assert filtered == [] and len(kept[4].green) == 0  # waiting, its points held by the stream
    levelled, placed = stream.placed(4, kept)
    assert filtered == [4]
    assert _same(levelled, expected[0]) and _same(placed, expected[1])


class _Stop(Exception):
    pass


@pytest.mark.parametrize("ground", [True, False])
@pytest.mark.parametrize("early", [False, True])
def test_the_pipeline_registers_what_levelling_and_filtering_all_together_gave(
    small_session: Path, monkeypatch: pytest.MonkeyPatch, early: bool, ground: bool
) -> None:
    """Read by the early reader or here, the field frame calibrated or from the reference's
    ground, the stations reach registration levelled and filtered as before streaming, and
    the scans kept until then hold no green points."""
    session, settings = load_session(small_session), ReconstructionSettings()
    session = session if ground else _without_ground(session)
    expected = _all_together(session, _scans(session, settings), 5, settings)
    seen: dict[str, object] = {}

    def summarise(local: object, filtered: object) -> object:
        seen["local"] = local
        return original_summarise(local, filtered)  # type: ignore[arg-type]

    def join(filtered: object, levelled: object, *args: object) -> object:
        seen["filtered"], seen["levelled"] = filtered, levelled
        raise _Stop

    original_summarise = stages.summarise
    monkeypatch.setattr(stages, "summarise", summarise)
    monkeypatch.setattr(stages, "join_stations", join)
    reader = start_reading(session, settings) if early else None
    assert not early or reader is not None
    with pytest.raises(_Stop):
        pipeline.run_reconstruction(session, settings, early=reader)
    assert _same(seen["levelled"], expected[0].value) and _same(seen["filtered"], expected[1])
    scans = seen["local"].value.scans  # type: ignore[attr-defined]
    assert sorted(scans) == [4, 5] and all(len(s.green) == 0 for s in scans.values())


class _Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_a_stage_inside_another_counts_only_as_itself(monkeypatch: pytest.MonkeyPatch) -> None:
    wall, cpu = _Clock(), _Clock()
    monkeypatch.setattr(progress.time, "perf_counter", wall)
    monkeypatch.setattr(progress, "cpu_seconds", cpu)
    timer = StageTimer()
    with timer.stage("reading"):
        wall.now, cpu.now = 1.0, 0.5
        with timer.stage("filtering"):
            wall.now, cpu.now = 3.0, 2.5
        wall.now, cpu.now = 3.5, 2.75
    with timer.stage("filtering"):
        wall.now, cpu.now = 4.0, 3.0
    assert timer.seconds == {"reading": 1.5, "filtering": 2.5}
    assert timer.cpu_seconds == {"reading": 0.75, "filtering": 2.25}
