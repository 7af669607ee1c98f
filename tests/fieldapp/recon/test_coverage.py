"""Plants the captures did not cover as planned are named: their nearest station has no usable
capture, or turned through fewer views than a turn."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from devices.geometry import Matrix4
from fieldapp.io.session import load_session
from fieldapp.recon.coverage import coverage_warnings, station_axes_xy
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.settings import ReconstructionSettings

GRID = {s: np.array([1.6 * ((s - 1) % 3), 1.6 * ((s - 1) // 3)]) for s in range(1, 10)}


def _moved(x: float, y: float, yaw_deg: float = 0.0) -> Matrix4:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:2, 3] = x, y
    return T


def test_a_plant_whose_nearest_station_was_not_read_is_named_with_the_distance_seen_from() -> None:
    plants = {1: np.array([0.4, 0.4]), 2: np.array([3.0, 3.0]), 3: np.array([1.8, 1.4])}
    read = {s: 8 for s in GRID if s != 9}
    warnings = coverage_warnings(plants, GRID, read, 8)
    assert warnings == [
        "plants seen only from farther stations, their traits may be low: the station nearest "
        "each has no usable capture: plant 2 (station 9; nearest read 1.4 m)"
    ]
    assert coverage_warnings(plants, GRID, {s: 8 for s in GRID}, 8) == []


def test_a_plant_whose_nearest_station_turned_part_way_is_named() -> None:
    plants = {1: np.array([0.4, 0.4]), 2: np.array([3.0, 3.0])}
    read = {s: 8 for s in GRID} | {1: 4}
    assert coverage_warnings(plants, GRID, read, 8) == [
        "plants seen from fewer sides, their traits may be low: the station nearest each "
        "turned through fewer than 8 views: plant 1 (station 1: 4 views)"
    ]


def test_stations_not_read_stand_where_the_station_calibration_puts_them() -> None:
    """The reference registered 2 m along x and turned 90 degrees: a station the calibration
    puts 1.6 m ahead of it (its x) stands 1.6 m along the output frame's y from it."""
    axis = np.array([0.0, 0.0, 0.2])  # on the camera's view axis, 20 cm ahead
    to_reference = {5: np.eye(4), 6: _moved(1.6, 0.0)}
    where = station_axes_xy({5: _moved(2.0, 0.0, 90.0)}, to_reference, 5, axis)
    np.testing.assert_allclose(where[5], [2.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(where[6], [2.0, 1.6], atol=1e-12)
    registered = station_axes_xy({5: np.eye(4), 6: _moved(1.0, 1.0)}, to_reference, 5, axis)
    np.testing.assert_allclose(registered[6], [1.0, 1.0], atol=1e-12)  # its own pose wins


def _named(warning: str) -> set[int]:
    return {int(m) for m in re.findall(r"plant (\d+) \(", warning)}


def test_a_mission_of_two_stations_names_every_plant_another_station_stands_nearer(
    small_session: Path,
) -> None:
    """Stations 4 and 5 of the 3 x 3 plot, two views each: the plants nearest another station
    (by the simulator's station positions, not the reconstruction's) are seen only from
    farther, the others from fewer sides."""
    result = run_reconstruction(load_session(small_session), ReconstructionSettings())
    truth = json.loads((small_session.parent / "full" / "truth.json").read_text())
    assert truth["rig"]["station_spacing_m"] == 1.6 and truth["rig"]["grid"] == 3
    assert result.frame == "map" and len(result.plants) >= 4
    nearest = {}
    for plant in result.plants:
        distance = {
            s: float(np.hypot(*(xy - [plant.traits.x_m, plant.traits.y_m])))
            for s, xy in GRID.items()
        }
        first, second = sorted(distance.values())[:2]
        assert second - first > 0.3  # no plant halfway between two stations
        nearest[plant.id] = min(distance, key=distance.__getitem__)
    far = [w for w in result.warnings if w.startswith("plants seen only from farther")]
    few = [w for w in result.warnings if w.startswith("plants seen from fewer sides")]
    assert len(far) == 1 and len(few) == 1
    assert _named(far[0]) == {p for p, s in nearest.items() if s not in (4, 5)}
    assert _named(few[0]) == {p for p, s in nearest.items() if s in (4, 5)}
