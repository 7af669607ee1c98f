"""Local reconstruction of a station: every view into view 0 by chaining the turntable step.

The paper's Eq. 9: with ``view_step`` = (R, t) mapping view k+1 into view k,
view j reaches view 0 as p0 = R^j p_j + (R^(j-1) + ... + R + I) t.
"""

from __future__ import annotations

from devices.geometry import Matrix4
from fieldapp.io.calibration import T_view0_view
from fieldapp.recon.cloud import Cloud

__all__ = ["T_view0_view", "station_cloud"]


def station_cloud(views: dict[int, Cloud], T_view_next: Matrix4) -> Cloud:
    """The views of one station (view index -> cloud in that view's camera frame) joined in
    the frame of view 0."""
    return Cloud.concatenate(
        [views[view].transformed(T_view0_view(T_view_next, view)) for view in sorted(views)]
    )
