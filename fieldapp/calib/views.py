"""View-to-view calibration of the turntable: ``view_step`` from a board seen at views k, k+1."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from devices.geometry import Matrix4, rotation_angle_deg
from fieldapp.calib.board import Board
from fieldapp.calib.observe import Observation, depth_problem, observe, paired_points
from fieldapp.calib.rigid import fit_rigid_weighted
from fieldapp.errors import FieldappError
from fieldapp.io.session import Capture, Session

MAX_ANGLE_DISAGREEMENT_DEG = 5.0


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


def check_order(a: Observation, b: Observation, board: Board) -> None:
    """Refuse pairs whose corner order is ambiguous or flipped between the two views."""
    if board.is_symmetric:
        raise FieldappError(
            f"a {board.cols} x {board.rows} board looks the same after a half turn, so the "
            "corner order between views is ambiguous: use a board whose inner corner counts "
            "differ by an odd number (e.g. 9 x 6)"
        )
    if None not in (a.corner_zero_dark, b.corner_zero_dark) and (
        a.corner_zero_dark != b.corner_zero_dark
    ):
        raise FieldappError(
            f"the corner order is flipped between {a.name} and {b.name} (the board was "
            "detected upside down in one of them): keep the board's long side level and "
            "capture again"
        )


def calibrate_view_step(
    session: Session, board: Board, station: int | None = None, nominal_deg: float | None = None
) -> ViewStepResult:
    """Solve ``view_step`` by weighted SVD on the corners seen at consecutive views."""
    if nominal_deg is None and session.calibration.view_step is not None:
        nominal_deg = session.calibration.view_step.angle_deg
    sources, targets, weights, names = [], [], [], []
    seen_once: list[str] = []
    for first, second in view_pairs(session, station):
        a, b = observe(session, first, board), observe(session, second, board)
        if a is None or b is None:
            seen_once += [o.name for o in (a, b) if o is not None]
            continue
        for observation in (a, b):
            problem = depth_problem(observation)
            if problem:
                raise FieldappError(problem)
        check_order(a, b, board)
        source, target, weight = paired_points(a, b)
        sources.append(source)
        targets.append(target)
        weights.append(weight)
        names.append(f"{a.name} -> {b.name}")
    if not names:
        if seen_once:
            raise FieldappError(
                f"the board was seen in only one view of a pair ({', '.join(seen_once)}): "
                "place it where views k and k+1 both see it whole"
            )
        raise FieldappError(
            f"no {board.cols} x {board.rows} board found in any pair of consecutive views"
            + (f" of station {station}" if station is not None else "")
        )
    fit = fit_rigid_weighted(np.vstack(sources), np.vstack(targets), np.concatenate(weights))
    angle = rotation_angle_deg(fit.T_target_source[:3, :3])
    if nominal_deg is not None and abs(angle - abs(nominal_deg)) > MAX_ANGLE_DISAGREEMENT_DEG:
        raise FieldappError(
            f"the solved turn is {angle:.1f} degrees but the table steps {abs(nominal_deg):g}: "
            "the board moved between the views, or the views are not consecutive"
        )
    return ViewStepResult(
        fit.T_target_source, angle, fit.rmse_m, names, sum(len(s) for s in sources)
    )
