"""Plants the captures did not cover as planned are named: their nearest station has no usable
capture, or turned through fewer views than a turn, or the views read saw them from one side
only."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from devices.geometry import Matrix4
from fieldapp.io.calibration import DepthCamera
from fieldapp.io.session import load_session
from fieldapp.recon.coverage import (
    ViewLimits,
    cut_tops,
    grouped_warnings,
    one_sided,
    station_axes_xy,
    uncovered,
    unseen_arc_deg,
    view_ceiling_m,
)
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.settings import ReconstructionSettings

GRID = {s: np.array([1.6 * ((s - 1) % 3), 1.6 * ((s - 1) // 3)]) for s in range(1, 10)}


def coverage_warnings(plants: dict, stations: dict, read: dict, turn: int) -> list[str]:
    return grouped_warnings(uncovered(plants, stations, read, turn).items(), turn)


def cut_tops_warning(tops: dict, *camera_and_limits: object) -> list[str]:
    return grouped_warnings(cut_tops(tops, *camera_and_limits).items(), 0)  # type: ignore[arg-type]


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


def test_stations_not_read_are_placed_from_the_anchor_when_the_reference_was_not_read() -> None:
    """The calibration's reference (5) has no capture; station 1 anchors the plot. Station 6
    stands 3.2 m along x and 1.6 m along y from station 1 by the calibration, wherever
    station 1 registered."""
    to_reference = {5: np.eye(4), 1: _moved(-1.6, -1.6), 6: _moved(1.6, 0.0)}
    where = station_axes_xy({1: _moved(10.0, 0.0)}, to_reference, 1, np.zeros(3))
    np.testing.assert_allclose(where[1], [10.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(where[5], [11.6, 1.6], atol=1e-12)
    np.testing.assert_allclose(where[6], [13.2, 1.6], atol=1e-12)


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
    for entry in result.plant_report()["plants"]:  # report.json: each plant's own caution
        far_from_its_station = nearest[entry["plant"]] not in (4, 5)
        kind = "seen only from farther stations" if far_from_its_station else "seen from fewer"
        assert entry["cautions"][0].startswith(kind)  # then maybe a top the views cut


KINECT = DepthCamera(width=512, height=424, fx=365.18, fy=364.49, cx=256.0, cy=209.59)
PAPER = ViewLimits(KINECT, 2.25, 0.5)
"""The paper's crop (2.25 m) and the sensor's near limit (0.5 m)."""


def _looking_along_x(height_m: float, pitch_deg: float = 45.0) -> np.ndarray:
    """(1, 4, 4) an OpenCV camera at (0, 0, ``height_m``) looking along +x, pitched down."""
    p = np.radians(pitch_deg)
    forward = np.array([np.cos(p), 0.0, -np.sin(p)])
    right = np.array([0.0, -1.0, 0.0])
    down = np.cross(forward, right)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([right, down, forward])
    T[:3, 3] = 0.0, 0.0, height_m
    return T[None]


def _around(azimuths_deg: list[float], distance_m: float = 1.2) -> np.ndarray:
    """(V, 4, 4) cameras 1.3 m up, ``distance_m`` from the origin at each azimuth, each
    looking at the origin's vertical, pitched 45 degrees down."""
    shots = []
    for azimuth in np.radians(azimuths_deg):
        T = _moved(distance_m * np.cos(azimuth), distance_m * np.sin(azimuth), 0.0)
        T[:2, :2] = [[-np.cos(azimuth), np.sin(azimuth)], [-np.sin(azimuth), -np.cos(azimuth)]]
        shots.append(T @ _looking_along_x(1.3)[0])
    return np.array(shots)


def test_the_unseen_arc_is_the_widest_gap_between_the_cameras_that_see_a_point() -> None:
    centre = np.array([0.0, 0.0, 0.15])
    assert unseen_arc_deg(centre, _around([0, 90, 180, 270]), PAPER) == pytest.approx(90)
    assert unseen_arc_deg(centre, _around([0, 90, 200]), PAPER) == pytest.approx(160)
    assert unseen_arc_deg(centre, _around([30]), PAPER) == 360.0
    # cameras that do not see it leave their side unseen: one beyond the 2.25 m crop, one
    # looking away, one so near that the point is under its image
    far, away, near = _around([0], 2.6), _around([90]), _around([180], 0.1)
    away[0, :3, :3] = away[0, :3, :3] @ np.diag([-1.0, 1.0, -1.0])  # turned round its axis
    seen = np.concatenate([far, away, near, _around([270])])
    assert unseen_arc_deg(centre, seen, PAPER) == 360.0
    wider = ViewLimits(KINECT, 3.0, 0.5)  # the far one sees it
    assert unseen_arc_deg(centre, seen, wider) == pytest.approx(270)


def test_a_plant_the_views_read_saw_from_one_side_only_is_named_when_the_plan_would_not() -> None:
    planned = _around([0, 90, 180, 270])
    centres = {1: np.array([0.0, 0.0, 0.15])}
    one_side = one_sided(centres, planned, planned[:2], PAPER)
    assert grouped_warnings(one_side.items(), 8) == [
        "plants seen from one side only, their traits may be low: the views read leave more "
        "than half a turn round each unseen, the planned views would not: plant 1 (unseen over "
        "270 deg round it, 90 as planned)"
    ]
    assert one_side[1].note() == (
        "seen from one side only, traits may be low (unseen over 270 deg round it, 90 as planned)"
    )
    assert one_sided(centres, planned, planned[[0, 2]], PAPER) == {}  # both sides
    assert one_sided(centres, planned[:2], planned[:2], PAPER) == {}  # as planned


def test_the_plant_beside_the_only_station_read_is_named_seen_from_one_side(
    tmp_path: Path,
) -> None:
    """A 2 x 2 plot captured from station 1 only, all eight views: the plant 0.5 m from it is
    seen close up on the station's side and from nowhere else (its other sides face the
    stations not read), the three others only from farther away."""
    from fieldapp.cli import main

    args = ["--grid", "2", "--stations", "1", "--seed", "11"]
    assert main(["simulate", "--out", str(tmp_path / "s"), *args]) == 0
    result = run_reconstruction(load_session(tmp_path / "s"), ReconstructionSettings())
    truth = json.loads((tmp_path / "s" / "truth.json").read_text())
    station_1 = np.array([truth["stations"]["1"]["nominal_pose"][k] for k in ("x", "y")])
    nearest = min(
        result.plants,
        key=lambda p: np.hypot(p.traits.x_m - station_1[0], p.traits.y_m - station_1[1]),
    )
    one = [w for w in result.warnings if w.startswith("plants seen from one side only")]
    far = [w for w in result.warnings if w.startswith("plants seen only from farther")]
    assert len(one) == 1 and _named(one[0]) == {nearest.id}
    assert len(far) == 1 and _named(far[0]) == {p.id for p in result.plants} - {nearest.id}


def test_the_ceiling_above_a_spot_is_where_the_view_stops_seeing_up_its_vertical() -> None:
    camera = _looking_along_x(1.3)
    above_axis = np.degrees(np.arctan(KINECT.cy / KINECT.fy))  # the top edge: 29.9 degrees
    edge = 1.3 - 1.0 * np.tan(np.radians(45.0 - above_axis))  # a metre ahead: 1.03 m
    assert view_ceiling_m(np.array([1.0, 0.0]), camera, PAPER) == pytest.approx(edge)
    # 20 cm ahead the vertical comes within 0.5 m of the camera first (depth along its axis)
    near = 1.3 + (0.2 * np.cos(np.radians(45.0)) - 0.5) / np.sin(np.radians(45.0))
    assert view_ceiling_m(np.array([0.2, 0.0]), camera, PAPER) == pytest.approx(near)
    # 2.2 m ahead the top edge (0.71 m) lies beyond the 2.25 m crop: nothing up there is kept
    assert view_ceiling_m(np.array([2.2, 0.0]), camera, PAPER) == float("-inf")
    assert view_ceiling_m(
        np.array([2.2, 0.0]), camera, ViewLimits(KINECT, 2.5, 0.5)
    ) == pytest.approx(1.3 - 2.2 * np.tan(np.radians(45.0 - above_axis)))
    assert view_ceiling_m(np.array([-1.0, 0.0]), camera, PAPER) == float("-inf")
    assert view_ceiling_m(np.array([1.0, 1.5]), camera, PAPER) == float("-inf")
    two = np.concatenate([camera, _looking_along_x(1.6)])  # the higher one sees higher
    assert view_ceiling_m(np.array([1.0, 0.0]), two, PAPER) == pytest.approx(edge + 0.3)


def test_a_vertical_near_the_images_side_leaves_it_through_that_side() -> None:
    """80 cm to the camera's left, a metre ahead: going up, the vertical leaves the image
    through its left edge (u = 0) at 0.69 m, before it reaches the top edge (1.03 m); a
    vertical is not an image column, so a view's stretch can end at any edge (the ceiling was
    -inf here: no view seen, a top named cut by a ceiling of "-inf cm")."""
    camera = _looking_along_x(1.3)
    cos = np.cos(np.radians(45.0))
    # u >= 0 <=> depth (cos 45 * (2.3 - z)) >= fx / cx * 0.8
    side = 2.3 - KINECT.fx / KINECT.cx * 0.8 / cos
    assert view_ceiling_m(np.array([1.0, 0.8]), camera, PAPER) == pytest.approx(side)
    assert 0.6 < side < 1.0


def test_a_plant_whose_top_is_at_the_ceiling_may_be_taller_than_measured() -> None:
    camera = _looking_along_x(1.3)
    tops = {1: np.array([1.0, 0.0, 1.025]), 2: np.array([1.0, 0.0, 0.95])}
    assert cut_tops_warning(tops, camera, PAPER, 1.5) == [
        "plants that may be taller than measured: their highest point lies where the views "
        "stop seeing: plant 1 (top 102 cm, views reach 103 cm)"
    ]
    high = _looking_along_x(3.0)  # sees far above the filters' limit there
    tops = {3: np.array([1.0, 0.0, 1.49]), 4: np.array([1.0, 0.0, 1.2])}
    assert cut_tops_warning(tops, high, PAPER, 1.5) == [
        "plants that may be taller than measured: their highest point lies where the views "
        "stop seeing: plant 3 (top 149 cm, views reach 150 cm)"
    ]
