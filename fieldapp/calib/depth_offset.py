"""A depth camera's static offset, from the checkerboards it sees.

A Kinect v2 unit adds a static 1-4 cm to every depth it measures, even after calibration
(``shared/KINECT-V2.md``: calibration tools estimate it per unit). Corners lifted with such
depth stand that much too far along the optical axis, and a board whose corners are lifted
looks larger by the offset over its distance: a 3 cm offset made a plot's plants 2 % wider and
its view step's features fit 1.5 times worse. The board's squares are known, so the offset is
what makes the lifted corners the board's own shape again: for each board, the offset and the
board's pose that bring its corners (each moved along its viewing ray by the offset) nearest
their lifted places, least squares (a bounded search over the offset, each offset's best pose
by Kabsch); the median over boards is the unit's.

Its precision is the intrinsics': the board's lateral size comes through the focal length, so
a focal length 0.5 % off reads as an offset of 0.5 % of the boards' distance (7 mm at 1.5 m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldapp.calib.board import Board
from fieldapp.calib.corners3d import Corners3D
from fieldapp.calib.observe import Observation
from fieldapp.calib.rigid import fit_rigid_weighted

MIN_CORNERS = 12
"""Lifted corners a board needs to tell its offset (the pose's six unknowns and the offset)."""
MAX_OFFSET_SHARE = 0.1
"""The largest offset searched, as a share of the board's distance: 13 cm at 1.3 m, three
times the largest a Kinect v2 is known for. A board needing more is not of the size told
(another board of the same pattern in view): it is left out."""
TOLERANCE_M = 1e-5


@dataclass(frozen=True)
class DepthOffset:
    """The unit's depth offset (``offset_m``, the median over ``boards`` boards) and how far
    the boards' own estimates spread about it (median absolute deviation, ``spread_m``)."""

    offset_m: float
    spread_m: float
    boards: int

    def text(self) -> str:
        """One line for the solver's report."""
        return (
            f"depth offset {1000 * self.offset_m:+.1f} mm (spread {1000 * self.spread_m:.1f} mm "
            f"over {self.boards} boards): taken off every depth read with this calibration"
        )


def board_offset_m(corners: Corners3D, board: Board) -> float | None:
    """The depth offset that makes one board's lifted corners (``corners``, in its camera
    frame, corner i of ``board.object_points_m()`` at row i) the board's shape: the offset
    whose corrected corners the board fits best (bounded scalar search up to
    :data:`MAX_OFFSET_SHARE` of its distance either way, each offset's best pose by Kabsch);
    ``None`` with fewer than :data:`MIN_CORNERS` lifted corners, or when the best offset is at
    the bound (not a board of the size told)."""
    from scipy.optimize import minimize_scalar

    valid = corners.valid
    if valid.sum() < MIN_CORNERS:
        return None
    lifted = corners.points_m[valid]
    model = board.object_points_m()[valid]
    depth = lifted[:, 2]
    rays = lifted / depth[:, None]  # z = 1: a point at depth z is z * ray

    def misfit(offset: float) -> float:
        return fit_rigid_weighted(model, rays * (depth - offset)[:, None]).rmse_m

    reach = MAX_OFFSET_SHARE * float(depth.mean())
    found = minimize_scalar(
        misfit, bounds=(-reach, reach), method="bounded", options={"xatol": TOLERANCE_M}
    )
    offset = float(found.x)
    return None if abs(offset) > reach - 10 * TOLERANCE_M else offset


def depth_offset(observations: list[Observation], board: Board) -> DepthOffset | None:
    """The unit's depth offset from every board seen (each board once per observation);
    ``None`` when no board had enough lifted corners."""
    estimates = [board_offset_m(o.corners, board) for o in observations]
    offsets = np.array([e for e in estimates if e is not None])
    if len(offsets) == 0:
        return None
    middle = float(np.median(offsets))
    return DepthOffset(middle, float(np.median(np.abs(offsets - middle))), len(offsets))


def without_offset(observation: Observation, offset_m: float) -> Observation:
    """``observation`` with its lifted corners moved ``offset_m`` nearer along their rays (the
    depth they were lifted with, less the offset); the weights stay."""
    points = observation.corners.points_m
    corrected = points * ((points[:, 2] - offset_m) / points[:, 2])[:, None]
    return Observation(
        observation.capture,
        observation.corners_px,
        observation.corner_zero_dark,
        Corners3D(corrected, observation.corners.weights),
    )
