"""Coarse station poses moved by where the base reported it stopped (``recon/arrival.py``).

A rig of known geometry: a camera on a tilted mount above the base's origin, stations on a
3 x 3 plan, the field frame turned and shifted against the map. The pre-calibration places the
stations as they stood when calibrated; the base then stops off each goal by a known planar
move and reports it. Moved by the reports, the coarse poses must be the true ones.
"""

from __future__ import annotations

import numpy as np
import pytest

from devices.geometry import Matrix4, invert, make_transform, rotation_x, rotation_z
from fieldapp.io.calibration import Calibration, StationPose, Stations
from fieldapp.recon.arrival import BaseMoves, Pose, T_map_base, move_coarse
from fieldapp.recon.settings import RegistrationSettings

REFERENCE = 5
T_BASE_CAMERA = make_transform(rotation_z(-90.0) @ rotation_x(-135.0), np.array([0.3, 0.1, 1.3]))
"""View 0 of the camera in the base's frame: 1.3 m up, 30 cm ahead of the axis, looking down
at 45 degrees (OpenCV axes)."""
T_FIELD_MAP = make_transform(rotation_z(33.0), np.array([-1.7, 0.4, 0.0]))
"""The field frame against the map's: any turn about z and shift."""


def _plan() -> dict[int, Pose]:
    return {
        1 + i + 3 * j: (1.6 * i, 1.6 * j, 90.0 * ((i + j) % 4)) for i in range(3) for j in range(3)
    }


def _axis() -> tuple[np.ndarray, np.ndarray]:
    T_camera_base = invert(T_BASE_CAMERA)
    return T_camera_base[:3, 3], T_camera_base[:3, :3] @ np.array([0.0, 0.0, 1.0])


def _field_cameras(poses: dict[int, Pose], reference_pose: Pose) -> dict[int, Matrix4]:
    """Each station's view 0 in a field frame anchored as the reconstruction anchors it: the
    reference camera where it stands in ``T_FIELD_MAP``'s frame of the calibration, whatever
    ``reference_pose`` it stands at now."""
    T_map_reference_camera = T_map_base(reference_pose) @ T_BASE_CAMERA
    T_field_reference = T_FIELD_MAP @ T_map_base(_plan()[REFERENCE]) @ T_BASE_CAMERA
    return {
        s: T_field_reference @ invert(T_map_reference_camera) @ T_map_base(p) @ T_BASE_CAMERA
        for s, p in poses.items()
    }


def _moved(pose: Pose, dx: float, dy: float, dyaw: float) -> Pose:
    return pose[0] + dx, pose[1] + dy, pose[2] + dyaw


def _reports(rng: np.random.Generator) -> dict[int, Pose]:
    return {
        s: _moved(p, *rng.normal(0.0, 0.08, 2), rng.normal(0.0, 4.0)) for s, p in _plan().items()
    }


def _move(reported: dict[int, Pose], settings: RegistrationSettings | None = None):  # type: ignore[no-untyped-def]
    coarse = _field_cameras(_plan(), _plan()[REFERENCE])
    point, direction = _axis()
    moves = BaseMoves(_plan(), reported, "plan")
    return move_coarse(
        coarse, REFERENCE, moves, point, direction, settings or RegistrationSettings()
    )


def _assert_poses_equal(a: dict[int, Matrix4], b: dict[int, Matrix4]) -> None:
    assert sorted(a) == sorted(b)
    for s in a:
        np.testing.assert_allclose(a[s], b[s], atol=1e-9, err_msg=f"station {s}")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_reported_stops_move_every_station_where_it_stood(seed: int) -> None:
    reported = _reports(np.random.default_rng(seed))
    moved = _move(reported)
    truth = _field_cameras(reported, reported[REFERENCE])
    _assert_poses_equal(moved.T_field_station, truth)
    assert not moved.warnings
    coarse = _field_cameras(_plan(), _plan()[REFERENCE])
    np.testing.assert_array_equal(moved.T_field_station[REFERENCE], coarse[REFERENCE])
    assert max(np.linalg.norm(coarse[s][:3, 3] - truth[s][:3, 3]) for s in truth) > 0.1
    assert moved.moved == set(truth) - {REFERENCE}


def test_a_base_reporting_in_another_frame_moves_the_stations_the_same() -> None:
    reported = _reports(np.random.default_rng(4))
    offset = make_transform(rotation_z(-1.0), np.array([0.05, -0.04, 0.0]))  # map re-localised

    def shifted(pose: Pose) -> Pose:
        T = offset @ T_map_base(pose)
        return float(T[0, 3]), float(T[1, 3]), pose[2] - 1.0

    elsewhere = {s: shifted(p) for s, p in reported.items()}
    moved = _move(elsewhere)
    assert not moved.warnings and len(moved.moved) == 8
    _assert_poses_equal(moved.T_field_station, _move(reported).T_field_station)


def test_a_move_beyond_the_limit_is_not_used_and_said() -> None:
    reported = _reports(np.random.default_rng(5))
    reported[3] = _moved(_plan()[3], 0.9, 0.0, 0.0)
    moved = _move(reported)
    assert len(moved.warnings) == 1 and moved.warnings[0].startswith("station 3: the base")
    coarse = _field_cameras(_plan(), _plan()[REFERENCE])
    expected = _field_cameras(reported, reported[REFERENCE]) | {3: coarse[3]}  # as calibrated
    _assert_poses_equal(moved.T_field_station, expected)
    loose = RegistrationSettings(max_base_move_m=1.0)
    _assert_poses_equal(
        _move(reported, loose).T_field_station, _field_cameras(reported, reported[REFERENCE])
    )


def test_stations_without_a_report_keep_the_calibrated_placement() -> None:
    reported = _reports(np.random.default_rng(6))
    del reported[7]
    moved = _move(reported)
    coarse = _field_cameras(_plan(), _plan()[REFERENCE])
    expected = _field_cameras(reported, reported[REFERENCE]) | {7: coarse[7]}
    _assert_poses_equal(moved.T_field_station, expected)
    del reported[REFERENCE]  # nothing to take the moves relative to: none is used
    _assert_poses_equal(_move(reported).T_field_station, coarse)


def test_a_base_reporting_far_from_every_station_moves_none() -> None:
    far = make_transform(rotation_z(-20.0), np.array([12.0, -3.0, 0.0]))  # odometry's frame
    reported = {s: (*(far @ T_map_base(p))[:2, 3], p[2] - 20.0) for s, p in _plan().items()}
    moved = _move(reported)
    assert len(moved.warnings) == 9 and not moved.moved
    _assert_poses_equal(moved.T_field_station, _field_cameras(_plan(), _plan()[REFERENCE]))


def test_calibration_keeps_the_base_poses_it_was_calibrated_at() -> None:
    stations = Stations(
        reference=5,
        to_reference={5: np.eye(4), 6: np.eye(4)},
        base_poses={
            5: StationPose(x=0.0, y=0.0, yaw_deg=0.0),
            6: StationPose(x=1.6, y=0.0, yaw_deg=1.0),
        },
    )
    document = {
        "format": "fieldapp-calibration/1",
        "depth_camera": {
            "width": 512,
            "height": 424,
            "fx": 365.0,
            "fy": 365.0,
            "cx": 256.0,
            "cy": 212.0,
        },
        "stations": stations.model_dump(mode="json"),
    }
    calibration = Calibration.model_validate(document)
    written = calibration.to_document()
    assert written["stations"]["base_poses"]["6"] == {"x": 1.6, "y": 0.0, "yaw_deg": 1.0}
    assert Calibration.model_validate(written).to_document() == written
