"""View-to-view calibration of the turntable: ``view_step`` from a board seen at views k, k+1."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, pose_error, rotation_angle_deg
from fieldapp.calib.board import Board
from fieldapp.calib.depth_offset import DepthOffset, depth_offset, without_offset
from fieldapp.calib.observe import (
    Observation,
    align_order,
    depth_problem,
    match_by_prior,
    observe_all,
    paired_points,
)
from fieldapp.calib.rigid import fit_rigid_weighted
from fieldapp.errors import FieldappError
from fieldapp.io.session import Capture, Session

MAX_PAIR_ROTATION_DEG = 3.0
"""A pair whose solved turn differs more from the table's nominal step is not the same board."""
MAX_PAIR_RMSE_M = 0.01
SAME_BOARD_M = 0.3
"""A board seen at views k and k+1 lands within this of itself through the nominal step."""


@dataclass
class ViewStepResult:
    T_view_k_view_k1: Matrix4
    """Maps view k+1 into view k (``view_step.matrix``)."""
    angle_deg: float
    """The rotation angle of the solved transform."""
    rmse_m: float
    """RMSE of the 3D feature points after the fit (the paper reports 1.8 mm)."""
    pairs: list[str]
    points: int
    warnings: list[str] = field(default_factory=list)
    depth_offset: DepthOffset | None = None
    """The unit's depth offset the boards show (``calib/depth_offset.py``; the one the
    session's calibration already took off included); the view step is solved without it."""


@dataclass
class _Pairs:
    sources: list[NDArray[np.float64]] = field(default_factory=list)
    targets: list[NDArray[np.float64]] = field(default_factory=list)
    weights: list[NDArray[np.float64]] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    seen_once: list[str] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)
    depth_offset: DepthOffset | None = None


def view_pairs(session: Session, station: int | None) -> list[tuple[Capture, Capture]]:
    """(view k, view k+1) capture pairs of one station and one target, tagged ones first."""
    groups: dict[tuple[int, str | None], dict[int, Capture]] = defaultdict(dict)
    for capture in session.captures:
        if station is None or capture.station == station:
            groups[(capture.station, capture.key[2])][capture.view] = capture
    ordered = sorted(groups.items(), key=lambda item: (item[0][1] is None, item[0][0]))
    return [
        (views[k], views[k + 1]) for _, views in ordered for k in sorted(views) if k + 1 in views
    ]


def _collect(session: Session, board: Board, station: int | None, prior: Matrix4) -> _Pairs:
    """The boards seen at consecutive views, their corners lifted without the depth offset
    they show (:func:`~fieldapp.calib.depth_offset.depth_offset` over every board seen)."""
    pairs = _Pairs()
    seen: list[tuple[list[Observation], list[Observation]]] = []
    for first, second in view_pairs(session, station):
        seen_a = _with_depth(observe_all(session, first, board), pairs)
        seen_b = _with_depth(observe_all(session, second, board), pairs)
        seen.append((seen_a, seen_b))
    pairs.depth_offset = depth_offset([o for a, b in seen for o in a + b], board)
    offset_m = pairs.depth_offset.offset_m if pairs.depth_offset else 0.0
    for seen_a, seen_b in seen:
        seen_a = [without_offset(o, offset_m) for o in seen_a]
        seen_b = [without_offset(o, offset_m) for o in seen_b]
        matched = match_by_prior(seen_a, seen_b, prior, SAME_BOARD_M, _centroid)
        if not matched:
            pairs.seen_once += [o.name for o in seen_a[:1] + seen_b[:1]]
            continue
        for a, b in matched:
            _add_pair(pairs, a, b, board, prior)
    return pairs


def _with_depth(sightings: list[Observation], pairs: _Pairs) -> list[Observation]:
    """The sightings whose corners have depth; the others are reported."""
    usable = []
    for sighting in sightings:
        problem = depth_problem(sighting)
        if problem:
            pairs.refused.append(problem)
        else:
            usable.append(sighting)
    return usable


def _centroid(observation: Observation) -> NDArray[np.float64]:
    return observation.centroid_m


def _add_pair(pairs: _Pairs, a: Observation, b: Observation, board: Board, prior: Matrix4) -> None:
    """Check one board seen at views k and k+1 and keep its corners, or say why not."""
    ordered_b = align_order(a, b, board, prior)
    if ordered_b is None:
        pairs.refused.append(f"{a.name} -> {b.name}: corner order cannot be told")
        return
    source, target, weight = paired_points(a, ordered_b)
    fit = fit_rigid_weighted(source, target, weight)
    rotation_off = pose_error(fit.T_target_source, prior)[1]
    if rotation_off > MAX_PAIR_ROTATION_DEG or fit.rmse_m > MAX_PAIR_RMSE_M:
        pairs.refused.append(
            f"{a.name} -> {b.name}: turn {rotation_angle_deg(fit.T_target_source[:3, :3]):.1f}"
            f" degrees, RMSE {1000 * fit.rmse_m:.1f} mm (board moved, or another board "
            "detected in one view)"
        )
        return
    pairs.sources.append(source)
    pairs.targets.append(target)
    pairs.weights.append(weight)
    pairs.names.append(f"{a.name} -> {b.name}")


def calibrate_view_step(
    session: Session, board: Board, station: int | None = None
) -> ViewStepResult:
    """Solve ``view_step`` by weighted SVD on the corners seen at consecutive views; the
    session's own (nominal) ``view_step`` is the prior that tells a wrong pair."""
    assert session.calibration.view_step is not None  # load_session guarantees it
    prior = session.calibration.view_step.matrix
    pairs = _collect(session, board, station, prior)
    if not pairs.names:
        raise FieldappError(_nothing_usable(pairs, board, station))
    fit = fit_rigid_weighted(
        np.vstack(pairs.sources), np.vstack(pairs.targets), np.concatenate(pairs.weights)
    )
    result = ViewStepResult(
        fit.T_target_source,
        rotation_angle_deg(fit.T_target_source[:3, :3]),
        fit.rmse_m,
        pairs.names,
        sum(len(s) for s in pairs.sources),
        depth_offset=_in_all(pairs.depth_offset, session),
    )
    result.warnings = [f"pair not used: {reason}" for reason in pairs.refused]
    if len(pairs.names) == 1:
        result.warnings.append(
            "only one pair of views used: capture the board at another "
            "station or height too, to check the result"
        )
    return result


def _in_all(found: DepthOffset | None, session: Session) -> DepthOffset | None:
    """``found`` (beyond what the session's calibration took off) as the unit's whole offset."""
    taken_off = session.calibration.depth_camera.depth_offset_m or 0.0
    return None if found is None else replace(found, offset_m=found.offset_m + taken_off)


def _nothing_usable(pairs: _Pairs, board: Board, station: int | None) -> str:
    if pairs.refused:
        return "no usable pair of views:\n  " + "\n  ".join(pairs.refused)
    if pairs.seen_once:
        return (
            f"the board was seen in only one view of a pair ({', '.join(pairs.seen_once)}): "
            "place it where views k and k+1 both see it whole"
        )
    where = f" of station {station}" if station is not None else ""
    return f"no {board.cols} x {board.rows} board found in any pair of consecutive views{where}"
