"""Local reconstruction of a station: every view into view 0 by chaining the turntable step.

The paper's Eq. 9: with ``view_step`` = (R, t) mapping view k+1 into view k,
view j reaches view 0 as p0 = R^j p_j + (R^(j-1) + ... + R + I) t.
"""

from __future__ import annotations

import numpy as np

from devices.geometry import Matrix4, make_transform
from fieldapp.recon.cloud import Cloud


def T_view0_view(T_view_next: Matrix4, view: int) -> Matrix4:
    """Maps view ``view`` into view 0, given the step that maps view k+1 into view k (Eq. 9)."""
    if view < 0:
        raise ValueError(f"view must be >= 0, got {view}")
    R, t = T_view_next[:3, :3], T_view_next[:3, 3]
    R_power = np.eye(3)
    t_sum = np.zeros(3)
    for _ in range(view):
        t_sum = t_sum + R_power @ t
        R_power = R_power @ R
    return make_transform(R_power, t_sum)


def station_cloud(views: dict[int, Cloud], T_view_next: Matrix4) -> Cloud:
    """The views of one station (view index -> cloud in that view's camera frame) joined in
    the frame of view 0."""
    return Cloud.concatenate(
        [views[view].transformed(T_view0_view(T_view_next, view)) for view in sorted(views)]
    )
