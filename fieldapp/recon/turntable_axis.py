"""The turntable's axis and placing a plant's views about it.

``view_step.matrix`` of a plant-on-turntable session is a rotation about the table's axis;
:func:`table_axis` recovers the axis, and :class:`TableAxis` turns a view about it by any
angle. :func:`place_views` joins the views by the commanded turns and, when asked, refines each
by ICP with one degree of freedom: the turn about the axis, so nothing else can drift.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, make_transform, transform_points
from fieldapp.errors import FieldappError

CAMERA_UP = np.array([0.0, -1.0, 0.0])
ICP_ABOVE_SURFACE_M = 0.02
ICP_DISTANCES_M = (0.01, 0.006, 0.004)
ICP_ITERATIONS = 15
ICP_MIN_PAIRS = 50
ICP_ROUNDS = 2
MAX_REFINEMENT_DEG = 5.0
SEARCH_STEP_DEG = 0.25


@dataclass(frozen=True)
class TableAxis:
    """The table's axis in the (fixed) camera frame: ``point_m`` (3,) on it, ``up`` (3,) unit,
    and ``rad_per_deg``: the signed turn about ``up`` that joins the views per degree of
    table angle (view_step's rotation over its ``angle_deg``)."""

    point_m: NDArray[np.float64]
    up: NDArray[np.float64]
    rad_per_deg: float

    def T_view0_view(self, turn_deg: float) -> Matrix4:
        """Maps a view taken ``turn_deg`` of table angle after view 0 into view 0."""
        R = _rotation(self.up, self.rad_per_deg * turn_deg)
        return make_transform(R, self.point_m - R @ self.point_m)

    def radius_height(
        self, points_m: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(N,) distance from the axis and (N,) height along it of ``points_m`` (N, 3)."""
        relative = points_m - self.point_m
        height = relative @ self.up
        radial = relative - height[:, None] * self.up
        return np.linalg.norm(radial, axis=1), height


def _rotation(axis: NDArray[np.float64], angle_rad: float) -> NDArray[np.float64]:
    """Rodrigues: the rotation by ``angle_rad`` about the unit ``axis``."""
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1.0 - np.cos(angle_rad)) * (K @ K)  # type: ignore[no-any-return]


def table_axis(T_view_next: Matrix4, step_deg: float) -> TableAxis:
    """The axis of ``view_step.matrix`` (a turn of ``step_deg`` of the table), pointing up in
    an upright camera."""
    R, t = T_view_next[:3, :3], T_view_next[:3, 3]
    angle = float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
    if angle < 1e-6:
        raise FieldappError("view_step.matrix does not turn: no table axis")
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    axis /= np.linalg.norm(axis)
    if axis @ CAMERA_UP < 0:
        axis, angle = -axis, -angle
    point = np.asarray(np.linalg.lstsq(np.eye(3) - R, t, rcond=None)[0], dtype=np.float64)
    return TableAxis(point, axis, angle / step_deg)


def place_views(
    commanded_deg: list[float],
    points_m: list[NDArray[np.float64]],
    axis: TableAxis,
    views: list[int],
    refine: bool,
    warnings: list[str],
) -> tuple[list[float], dict[str, object]]:
    """Each view's turn from the first (table degrees): the commanded turns
    (``commanded_deg``, one per view), refined when ``refine`` by ICP of the views' plant points
    (``points_m``, each (N, 3) in its camera frame) about the axis: first each view against the
    views already placed, then (``ICP_ROUNDS`` times) each against all the others, the first
    staying put. ``views``: the view numbers, for the warnings."""
    commanded = [angle - commanded_deg[0] for angle in commanded_deg]
    turns = list(commanded)
    if not refine:
        return turns, {"view_turns_deg": [round(t, 3) for t in turns], "refined_by_icp": False}
    failed: set[int] = set()
    for round_ in range(ICP_ROUNDS + 1):
        for i in range(1, len(turns)):
            if round_ == 0:
                turns[i] = turns[i - 1] + commanded[i] - commanded[i - 1]
            others = range(i) if round_ == 0 else (j for j in range(len(turns)) if j != i)
            target = np.concatenate(
                [transform_points(axis.T_view0_view(turns[j]), points_m[j]) for j in others]
            )
            correction = _icp_about_axis(points_m[i], target, axis, turns[i])
            if correction is None:
                failed.add(views[i])
            else:
                turns[i] += correction
    for i, turn in enumerate(turns):
        if abs(turn - commanded[i]) > MAX_REFINEMENT_DEG * 2:
            failed.add(views[i])
            turns[i] = commanded[i]
    if failed:
        warnings.append(
            f"views {', '.join(map(str, sorted(failed)))}: ICP about the table's axis failed; "
            "the commanded angles are kept"
        )
    return turns, {
        "view_turns_deg": [round(t, 3) for t in turns],
        "icp_corrections_deg": [round(t - c, 3) for t, c in zip(turns, commanded, strict=True)],
        "refined_by_icp": True,
    }


def _icp_about_axis(
    source_m: NDArray[np.float64], target_m: NDArray[np.float64], axis: TableAxis, turn_deg: float
) -> float | None:
    """The correction (table degrees) to ``turn_deg`` that best lays ``source_m`` (N, 3), a
    view's plant points in its camera frame, on ``target_m`` (M, 3) in view 0: the best of a
    search over +-``MAX_REFINEMENT_DEG``, then ICP with one degree of freedom (the turn about
    the axis), coarse to fine; ``None`` with too few points or pairs."""
    if len(source_m) < ICP_MIN_PAIRS or len(target_m) < ICP_MIN_PAIRS:
        return None
    tree = cKDTree(target_m)

    def cost(delta: float) -> float:
        moved = transform_points(axis.T_view0_view(turn_deg + delta), source_m)
        distance, _ = tree.query(moved, distance_upper_bound=ICP_DISTANCES_M[0])
        return float(np.mean(np.minimum(distance, ICP_DISTANCES_M[0])))

    candidates = np.arange(-MAX_REFINEMENT_DEG, MAX_REFINEMENT_DEG + 1e-9, SEARCH_STEP_DEG)
    delta = float(candidates[np.argmin([cost(c) for c in candidates])])
    for max_distance in ICP_DISTANCES_M:
        for _ in range(ICP_ITERATIONS):
            moved = transform_points(axis.T_view0_view(turn_deg + delta), source_m)
            distance, index = tree.query(moved, distance_upper_bound=max_distance)
            paired = np.isfinite(distance)
            if paired.sum() < ICP_MIN_PAIRS:
                return None
            s = _flat(moved[paired] - axis.point_m, axis.up)
            t = _flat(target_m[index[paired]] - axis.point_m, axis.up)
            phi = np.arctan2(np.sum(np.cross(s, t) @ axis.up), np.sum(s * t))
            step = float(phi) / axis.rad_per_deg
            delta += step
            if abs(step) < 1e-3:
                break
    return delta


def _flat(vectors: NDArray[np.float64], up: NDArray[np.float64]) -> NDArray[np.float64]:
    """``vectors`` (N, 3) without their component along ``up``."""
    return vectors - (vectors @ up)[:, None] * up
