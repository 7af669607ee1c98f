"""Coarse station poses moved by where the base reported it stopped.

``stations.to_reference`` was measured with the base standing at its calibration poses: those
``fieldapp calibrate stations`` recorded from its captures' ``base_pose`` (the calibration's
``stations.base_poses``), else the mission plan's station poses, the goals the base is sent
to. A base never stops on its goal: it stops within its goal tolerance, *by its own estimate*,
and a session's captures carry that estimate (``base_pose``, map frame). The difference
between where the base reported standing and where it stood when calibrated is the part of its
arrival error the base knows; what is left is its localisation error. So when a first
registration leaves stations coarse (``stages.join_stations``), it runs again with each
station's levelled pose moved by that difference: from the localisation error instead of the
whole arrival error (the simulator splits a 10 cm / 5 degree arrival into 8 cm / 4 degrees of
stopping, reported, and 6 cm / 3 degrees of localisation). Not in the first run: it places the
stations as well, but not identically, and on touching canopies a millimetre decides some leaf
tips; a plot that registers the first time is registered as before.

The move is a planar one (a turn about the vertical and a shift) in the map frame, taken into
the field frame by the 2-D fit of the calibrated stations' turntable axes onto their
calibration poses (:func:`fieldapp.recon.mapframe.map_alignment`), and taken relative to the
reference station's own move, so the reference (which defines the field frame) stays where it
is. A constant offset between the base's map and the plan's frame (a base reporting in another
frame) cancels in that difference. A report more than ``max_base_move_m`` / ``_deg`` from its
station's calibration pose (in the base's own frame) is not used, with a warning: a base
reporting in another frame, or a jump of its localisation, is more likely than such an
arrival. A station without a usable report keeps its calibrated placement; without the
reference's, no station is moved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert, make_transform, rotation_angle_deg, rotation_z
from fieldapp.io.session import Session, reported_base_poses
from fieldapp.recon.mapframe import map_alignment
from fieldapp.recon.settings import RegistrationSettings

Pose = tuple[float, float, float]
"""A base pose in the map frame: x (m), y (m), yaw (degrees)."""


@dataclass(frozen=True)
class BaseMoves:
    """Where the base stood when the stations were calibrated (``calibrated``, by station) and
    where it reported standing in this session (``reported``); ``source`` says where the
    calibrated poses came from (``"calibration"`` or ``"plan"``)."""

    calibrated: dict[int, Pose]
    reported: dict[int, Pose]
    source: str


@dataclass(frozen=True)
class Moved:
    """The coarse poses after the moves, the stations moved, and the warnings."""

    T_field_station: dict[int, Matrix4]
    moved: frozenset[int]
    warnings: tuple[str, ...]


def base_moves(session: Session) -> BaseMoves | None:
    """The session's reported base poses and the calibration poses they are compared with;
    ``None`` when the session reports no pose, or nothing says where the base stood when the
    stations were calibrated."""
    reported = reported_base_poses(session)
    if not reported:
        return None
    stations = session.calibration.stations
    if stations is not None and stations.base_poses:
        calibrated = {s: (p.x, p.y, p.yaw_deg) for s, p in stations.base_poses.items()}
        return BaseMoves(calibrated, reported, "calibration")
    plan = session.document.plan
    if plan is not None and plan.stations:
        calibrated = {p.number: (p.x_m, p.y_m, p.yaw_deg) for p in plan.stations}
        return BaseMoves(calibrated, reported, "plan")
    return None


def T_map_base(pose: Pose) -> Matrix4:
    """The base's planar pose as a 4 x 4 transform (a turn about z, a shift in x and y)."""
    x, y, yaw_deg = pose
    return make_transform(rotation_z(yaw_deg), np.array([x, y, 0.0]))


def move_coarse(
    T_field_coarse: dict[int, Matrix4],
    reference: int,
    moves: BaseMoves,
    axis_point_camera: NDArray[np.float64],
    axis_direction_camera: NDArray[np.float64] | None,
    settings: RegistrationSettings,
) -> Moved:
    """``T_field_coarse`` (each station's view 0 placed by the calibration) moved by each
    station's reported move relative to ``reference``'s (see the module's docstring). A
    station without a report, or whose move is beyond the limits, keeps its calibrated
    placement; without the reference's report none is moved."""
    placed = {s: T for s, T in T_field_coarse.items() if s in moves.calibrated}
    T_map_field = map_alignment(moves.calibrated, placed, axis_point_camera, axis_direction_camera)
    if T_map_field is None:
        return Moved(dict(T_field_coarse), frozenset(), ())
    usable, warnings = {}, []
    for station in sorted(set(placed) & set(moves.reported)):
        shift_m, turn_deg = _size(moves, station)
        if shift_m <= settings.max_base_move_m and turn_deg <= settings.max_base_move_deg:
            usable[station] = _move(moves, station)
            continue
        warnings.append(
            f"station {station}: the base reported standing {1000 * shift_m:.0f} mm / "
            f"{turn_deg:.1f} deg from where it stood when calibrated ({moves.source}); more "
            f"than {1000 * settings.max_base_move_m:.0f} mm / {settings.max_base_move_deg:g} "
            "deg, so its report is not used"
        )
    if reference not in usable:
        return Moved(dict(T_field_coarse), frozenset(), tuple(warnings))
    T_field_map = invert(T_map_field)
    D_reference_inv = invert(usable[reference])
    moved = dict(T_field_coarse)
    for station in set(usable) - {reference}:
        E = D_reference_inv @ usable[station]
        moved[station] = T_field_map @ E @ T_map_field @ T_field_coarse[station]
    return Moved(moved, frozenset(usable) - {reference}, tuple(warnings))


def _move(moves: BaseMoves, station: int) -> Matrix4:
    """The planar move (map frame) from where the base stood at ``station`` when calibrated to
    where it reported standing."""
    return T_map_base(moves.reported[station]) @ invert(T_map_base(moves.calibrated[station]))


def _size(moves: BaseMoves, station: int) -> tuple[float, float]:
    """How far the base reported standing from where it stood at ``station`` when calibrated,
    in its own frame: (m, degrees)."""
    local = invert(T_map_base(moves.calibrated[station])) @ T_map_base(moves.reported[station])
    return float(np.linalg.norm(local[:2, 3])), rotation_angle_deg(local[:3, :3])
