"""The reconstruction's stages are pure functions, and the pipeline calling them keeps its
progress, its cancellation between steps and its warnings in the order of the steps.

Everything runs on the small shared session (2 stations x 2 views at half resolution, about
0.1 s of CPU per reconstruction)."""

from __future__ import annotations

import copy
import dataclasses
import itertools
import json
import math
import shutil
from collections.abc import Callable, Generator
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import pytest
from pydantic import BaseModel

from fieldapp.io.session import Session, load_session
from fieldapp.recon import stages
from fieldapp.recon.backproject import ray_table
from fieldapp.recon.mapframe import station_map_poses
from fieldapp.recon.pipeline import reconstruct
from fieldapp.recon.progress import STAGES, Progress
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.scans import captures_by_station
from fieldapp.recon.settings import ReconstructionSettings

T = TypeVar("T")
R = TypeVar("R")


def _same(a: object, b: object) -> bool:
    """Equal in value all the way down: arrays element by element (NaN equal to NaN) with
    their dtypes, dataclasses and pydantic models field by field, containers item by item and
    in order."""
    if isinstance(a, np.ndarray):
        return (
            isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")
        )
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(
            _same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a)
        )
    if isinstance(a, BaseModel):  # a calibration or settings section: field by field, extras too
        return type(a) is type(b) and _same(dict(a), dict(b))
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return type(a) is type(b) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    return a == b


def _finish(steps: Generator[Any, None, R]) -> R:
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]


def _twice(stage: Callable[..., T], *args: Any) -> T:
    """``stage(*args)`` run twice: the same result both times, and every argument but the
    session (read-only: the images it reads) unchanged. Generator stages are run to the end."""
    kept = [copy.deepcopy(a) for a in args if not isinstance(a, Session)]
    results = []
    for _ in range(2):
        result = stage(*args)
        results.append(_finish(result) if isinstance(result, Generator) else result)
    assert _same(results[0], results[1]), f"{stage.__name__}: another result the second time"
    after = [a for a in args if not isinstance(a, Session)]
    assert _same(after, kept), f"{stage.__name__} changed its arguments"
    return results[0]  # type: ignore[no-any-return]


def test_every_stage_gives_the_same_result_twice_and_leaves_its_arguments_alone(
    small_session: Path,
) -> None:
    session, settings = load_session(small_session), ReconstructionSettings()
    view_step, stations = session.calibration.view_step, session.calibration.stations
    assert view_step is not None and stations is not None
    rays = ray_table(session.calibration.depth_camera.intrinsics())
    read = {
        station: _twice(
            stages.station_scan,
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
    local = _twice(stages.calibrated_scans, read, stations.to_reference)
    assert sorted(local.value.scans) == [4, 5] and local.warnings == ()
    reference = _twice(stages.anchor, stations.reference, local.value.scans, stations.to_reference)
    levelled = _twice(stages.level, local.value, session.calibration, 5, settings.ground)
    filtered = {
        s: _twice(stages.filter_plants, scan, levelled.value[s], settings.filters, settings.ground)
        for s, scan in local.value.scans.items()
    }
    _twice(stages.summarise, local, filtered)
    joined = _twice(
        stages.join_stations, filtered, levelled.value, view_step, 5, settings.registration, 1
    )
    fused = _twice(stages.fuse, filtered, joined.value, settings.filters, 1)
    placed = _twice(stages.on_map, fused, joined.value, station_map_poses(session), view_step)
    grid = _twice(stages.planting_grid, session, placed.T_map_field)
    found = _twice(stages.find_plants, placed, settings.plants, 0.15, grid.value.nodes)
    organs = _twice(stages.organs, found.value.plants)
    assert reference.value == 5 and placed.T_map_field is not None and len(fused.cloud) > 0
    assert found.value.plants and set(organs) == {p.id for p in found.value.plants}


def test_a_stage_returns_its_warnings_and_never_adds_to_anothers() -> None:
    identity = np.eye(4)
    far = np.eye(4)
    far[0, 3] = 3.2
    to_reference = {5: identity, 4: far, 6: far.copy()}
    anchored = stages.anchor(5, [4, 6], to_reference)
    assert anchored.value == 4  # the nearest, the lower number on a tie
    assert anchored.warnings == (
        "reference station 5 has no usable capture: station 4 anchors the plot",
    )
    assert stages.anchor(5, [4, 5], to_reference) == stages.Staged(5, ())
    read: dict[int, stages.Staged[Any]] = {
        3: stages.Staged(None, ("station 3 view 0 skipped: unreadable",)),
        4: stages.Staged(object(), ("station 4 view 1 skipped: unreadable",)),
    }
    local = stages.calibrated_scans(read, [5])
    assert local.value.scans == {}
    assert local.warnings == (  # station by station, a station never read is not "skipped"
        "station 3 view 0 skipped: unreadable",
        "station 4 view 1 skipped: unreadable",
        "station 4 has no to_reference calibration: skipped",
    )
    assert stages.missing_captures([]) == ()
    assert stages.missing_captures([(1, 0), (2, 7)]) == ("2 captures missing: s1 v0, s2 v7",)


def _recording(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every stage the pipeline calls, by name, in the order called."""
    calls: list[str] = []
    for name in (
        "station_scan",
        "turntable_scan",
        "calibrated_scans",
        "anchor",
        "level",
        "filter_plants",
        "summarise",
        "join_stations",
        "fuse",
        "on_map",
        "planting_grid",
        "find_plants",
        "organs",
    ):
        stage = getattr(stages, name)

        def recorded(*args: Any, _stage: Any = stage, _name: str = name, **kwargs: Any) -> Any:
            calls.append(_name)
            return _stage(*args, **kwargs)

        monkeypatch.setattr(stages, name, recorded)
    return calls


def test_closing_the_generator_after_any_event_runs_no_further_stage(
    small_session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session, settings = load_session(small_session), ReconstructionSettings()
    calls = _recording(monkeypatch)
    events: list[Progress] = []
    called_before: list[int] = []  # how many stages had been called when each event came
    steps = reconstruct(session, settings)
    while True:
        try:
            events.append(next(steps))
        except StopIteration as done:
            result: Reconstruction = done.value
            break
        called_before.append(len(calls))
    everything = list(calls)
    # each station levelled and filtered as soon as it is read (the simulator calibrates the
    # ground, so the field frame is known from the start: test_streaming.py)
    assert everything[:5] == [
        "station_scan",
        "filter_plants",
        "station_scan",
        "filter_plants",
        "calibrated_scans",
    ]
    assert everything[-1] == "organs" and result.plants
    order = list(STAGES)
    assert [order.index(e.stage) for e in events] == sorted(order.index(e.stage) for e in events)
    assert all(a.fraction <= b.fraction for a, b in itertools.pairwise(events))
    assert [(e.stage, e.message) for e in events if e.stage != "registration"] == [
        ("local reconstruction", "station 1 of 2"),
        ("local reconstruction", "station 2 of 2"),
        ("levelling", "stations levelled"),
        ("filtering", "station 4 filtered"),
        ("filtering", "station 5 filtered"),
        ("plants", "outliers removed"),
        ("traits", f"{len(result.plants)} plants"),
    ]
    assert events[-1].fraction == 1.0
    assert [e.message for e in events if e.stage == "registration"][-1] == "2 stations placed"
    new_calls = [everything[a:b] for a, b in itertools.pairwise([0, *called_before])]
    assert new_calls == _expected_calls(events)  # one station's work per per-station event
    for taken in range(1, len(events) + 1):
        calls.clear()
        steps = reconstruct(session, settings)
        for _ in range(taken):
            next(steps)
        steps.close()
        with pytest.raises(StopIteration):
            next(steps)
        assert calls == everything[: called_before[taken - 1]], f"after event {taken}"


def _expected_calls(events: list[Progress]) -> list[list[str]]:
    """The stages that run before each event, when every step reports as soon as it is done."""
    before = {
        "local reconstruction": ["station_scan", "filter_plants"],
        "levelling": ["calibrated_scans", "anchor"],
        "filtering": [],
        "registration": ["summarise", "join_stations"],
        "plants": ["fuse"],
        "traits": ["on_map", "planting_grid", "find_plants", "organs"],
    }
    first = [i == 0 or e.stage != events[i - 1].stage for i, e in enumerate(events)]
    return [
        before[e.stage] if is_first or e.stage in ("local reconstruction", "filtering") else []
        for e, is_first in zip(events, first, strict=True)
    ]


def test_warnings_come_in_the_order_of_the_steps(small_session: Path, tmp_path: Path) -> None:
    """Missing captures, then station by station what reading skipped (a station the
    calibration does not place, a view), in that order."""
    folder = tmp_path / "damaged"
    shutil.copytree(small_session, folder)
    (folder / "frames" / "s05" / "v1" / "depth.png").write_bytes(b"not a png")
    calibration = json.loads((folder / "calibration.json").read_text())
    del calibration["stations"]["to_reference"]["4"]
    (folder / "calibration.json").write_text(json.dumps(calibration))
    result = _finish(reconstruct(load_session(folder), ReconstructionSettings()))
    expected = [
        "captures missing: ",
        "station 4 has no to_reference calibration: skipped",
        "station 5 view 1 skipped: ",
    ]
    found = [next(i for i, w in enumerate(result.warnings) if e in w) for e in expected]
    assert found == sorted(found) == [0, 1, 2], result.warnings
    assert sorted(result.registrations) == [5]
