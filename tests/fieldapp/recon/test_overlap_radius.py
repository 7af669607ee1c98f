"""Where stations stand nearer together than the paper's, registration takes each station's
points within the paper's reach in spacings of one of its views' optical centres
(``backproject.overlap_radius``, ``stages._registration_points``), while the plants keep the
whole crop: so a station overlaps its neighbours as on the paper's rig, not every station of
the plot (three times the registration's CPU on stations 0.8 m apart)."""

from __future__ import annotations

import numpy as np

from devices.geometry import make_transform
from fieldapp.io.calibration import ViewStep
from fieldapp.recon.stages import _registration_points


class _Filtered:
    def __init__(self, points: np.ndarray) -> None:
        self.points = points

    def registration_points(self, include_soil: bool) -> np.ndarray:
        return self.points


def _quarter_turns() -> ViewStep:
    """Four views a quarter turn apart about a vertical axis 0.2 m before view 0's camera."""
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    axis = np.array([0.2, 0.0, 0.0])
    step = make_transform(turn, axis - turn @ axis)
    return ViewStep(angle_deg=90.0, matrix=step.tolist())


def test_registration_keeps_the_points_within_reach_of_a_view() -> None:
    view_step = _quarter_turns()
    centres = [view_step.T_view0_view(v)[:3, 3] for v in range(4)]
    assert np.allclose(centres[2], [0.4, 0.0, 0.0])  # half a turn: across the axis
    points = np.array([[1.0, 0.0, 0.0], [1.35, 0.0, 0.0], [0.2, 1.1, 0.0], [0.2, 1.5, 0.0]])
    filtered = {1: _Filtered(points)}
    level = {1: np.eye(4)}
    kept = _registration_points(filtered, level, True, view_step, 1.0)[1]
    # 0.6 m from the view across the axis; 0.95 m from it; 0.9 m from the quarter turn's
    # centre (0.2, 0.2); 1.3 m from every view
    np.testing.assert_array_equal(kept, points[:3])
    whole = _registration_points(filtered, level, True, view_step, None)[1]
    np.testing.assert_array_equal(whole, points)
