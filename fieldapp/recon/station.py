"""Local reconstruction of a station: every view into view 0 by chaining the turntable step.

The paper's Eq. 9: with ``view_step`` = (R, t) mapping view k+1 into view k,
view j reaches view 0 as p0 = R^j p_j + (R^(j-1) + ... + R + I) t.

A capture that records the angle its table reached (``angle_deg``, session format) is placed
at that angle: the chain to its view, then what is left of the turn about the step's own axis.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from devices.geometry import Matrix4, transform_points
from fieldapp.io.calibration import T_view0_view
from fieldapp.recon.cloud import Cloud, joined_mixed

__all__ = ["MAX_ANGLE_OFF_DEG", "T_view0_reached", "T_view0_view", "angle_off_deg", "station_cloud"]

MAX_ANGLE_OFF_DEG = 5.0
"""A recorded table angle further than this from its view's (view x step, modulo a turn) is
not taken for the angle reached: the view is placed by the chain alone, with a warning. A table
that stops within its driver's tolerance (0.2 degrees) or a few tenths off is placed where it
stopped; an angle written in another convention (a turn the other way, an offset origin) is
no such small difference."""


def angle_off_deg(view: int, angle_deg: float | None, step_deg: float) -> float:
    """How far the recorded ``angle_deg`` is from view ``view``'s nominal angle, in
    (-180, 180] (0 when no angle is recorded)."""
    if angle_deg is None:
        return 0.0
    off = (angle_deg - view * step_deg) % 360.0
    return off - 360.0 if off > 180.0 else off


def T_view0_reached(T_view_next: Matrix4, step_deg: float, view: int, off_deg: float) -> Matrix4:
    """Maps view ``view``, taken with the table ``off_deg`` past its nominal angle, into view
    0: the chained step to view ``view`` (Eq. 9), then ``off_deg`` about the step's axis (the
    axis has the same coordinates in every view's frame, each view being a turn about it)."""
    nominal = T_view0_view(T_view_next, view)
    if off_deg == 0.0:
        return nominal
    from fieldapp.recon.turntable_axis import table_axis  # SciPy: not before the reader forks

    return nominal @ table_axis(T_view_next, step_deg).T_view0_view(off_deg)


def station_cloud(
    views: dict[int, Cloud], T_view_next: Matrix4, placed: Mapping[int, Matrix4] | None = None
) -> Cloud:
    """The views of one station (view index -> cloud in that view's camera frame) joined in
    the frame of view 0; ``placed``: a view's own transform into view 0 (the angle its table
    reached, :func:`T_view0_reached`) instead of the chain."""
    placed = placed or {}
    # each view transformed straight into its rows of the station's arrays: transformed
    # copies and then a concatenation held a depth-only station's every point (30-40 MB) twice
    # over (RECONSTRUCTION.md, "Plants told by geometry in the sun")
    points = np.empty((sum(len(cloud) for cloud in views.values()), 3))
    colors = np.empty((len(points), 3), dtype=np.uint8)
    start = 0
    for view in sorted(views):
        cloud, end = views[view], start + len(views[view])
        T = placed[view] if view in placed else T_view0_view(T_view_next, view)
        points[start:end] = transform_points(T, cloud.points)  # one view's copy at a time
        colors[start:end] = cloud.colors
        start = end
    return Cloud(points, colors, joined_mixed([views[view] for view in sorted(views)]))
