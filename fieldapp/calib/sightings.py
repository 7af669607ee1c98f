"""The boards a station saw: every sighting of one physical board, grouped by position."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from devices.geometry import transform_points
from fieldapp.calib.board import Board
from fieldapp.calib.corners3d import Corners3D
from fieldapp.calib.observe import Observation, align_order, depth_problem, observe_all
from fieldapp.io.calibration import ViewStep
from fieldapp.io.session import Session

SAME_BOARD_M = 0.15
"""Sightings of one station closer than this (in its view-0 frame) are the same board."""


def in_view0(observation: Observation, view_step: ViewStep) -> Observation:
    """The observation's 3D corners moved from its view's frame into view 0's."""
    T = view_step.T_view0_view(observation.capture.view)
    corners = Corners3D(
        transform_points(T, observation.corners.points_m), observation.corners.weights
    )
    return Observation(
        observation.capture, observation.corners_px, observation.corner_zero_dark, corners
    )


@dataclass(eq=False)
class BoardGroup:
    """Every sighting of one board from one station. ``members`` stay in their own view's frame
    with their corners in the order of ``members[0]``; ``average`` is their weighted mean in the
    station's view-0 frame."""

    station: int
    members: list[Observation] = field(default_factory=list)
    average: Observation | None = None

    @property
    def mean(self) -> Observation:
        assert self.average is not None
        return self.average


def board_groups(
    session: Session, board: Board, view_step: ViewStep, use_untagged: bool
) -> dict[int, list[BoardGroup]]:
    """station -> its boards. Captures tagged with a ``target`` always count, untagged ones
    when ``use_untagged``; sightings without usable depth are left out."""
    groups: dict[int, list[BoardGroup]] = defaultdict(list)
    for capture in session.captures:
        if capture.key[2] is None and not use_untagged:
            continue
        for observation in observe_all(session, capture, board):
            if depth_problem(observation) is None:
                _add(groups[capture.station], observation, board, view_step)
    for station_groups in groups.values():
        for group in station_groups:
            group.average = _average([in_view0(m, view_step) for m in group.members])
    return dict(groups)


def _add(groups: list[BoardGroup], new: Observation, board: Board, view_step: ViewStep) -> None:
    new0 = in_view0(new, view_step)
    for group in groups:
        first0 = in_view0(group.members[0], view_step)
        if np.linalg.norm(first0.centroid_m - new0.centroid_m) < SAME_BOARD_M:
            aligned = align_order(first0, new0, board, np.eye(4))  # same frame: no motion
            if aligned is not None:
                group.members.append(new if aligned is new0 else new.reversed())
            return
    groups.append(BoardGroup(new.capture.station, [new]))


def _average(sightings: list[Observation]) -> Observation:
    """Weighted mean of a board's corners over several sightings in one frame."""
    points = np.stack([o.corners.points_m for o in sightings])
    weights = np.stack([np.where(o.corners.valid, o.corners.weights, 0.0) for o in sightings])
    total = weights.sum(axis=0)
    summed = np.einsum("kn,knd->nd", weights, np.nan_to_num(points))
    mean = summed / np.maximum(total, 1e-30)[:, None]
    mean[total == 0] = np.nan
    first = sightings[0]
    return Observation(
        first.capture, first.corners_px, first.corner_zero_dark, Corners3D(mean, total)
    )
