"""Joint refinement of the station poses and the turntable's view step over every board sighting.

Each sighting of a board (station s, view v, corners p) must land where the board's best
sighting lands in the reference frame: T_reference_s S^v p. Solving for all station poses and S
at once uses every corner, so errors no longer pile up along the spanning tree, and the view
step is checked by every board seen at two views.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from devices.geometry import Matrix4, make_transform, transform_points
from fieldapp.calib.observe import Observation
from fieldapp.calib.sightings import BoardGroup

ROBUST_SIGMAS = 3.0
"""Residuals are in standard deviations of each corner; beyond this the loss turns linear."""


@dataclass
class BundleResult:
    T_reference_station: dict[int, Matrix4]
    T_view_k_view_k1: Matrix4
    rmse_m: float
    boards: int
    sightings: int


class _Boards:
    """Union-find over board groups linked across stations, tracking corner-order flips."""

    def __init__(self) -> None:
        self.parent: dict[BoardGroup, BoardGroup] = {}
        self.flip: dict[BoardGroup, bool] = {}

    def find(self, group: BoardGroup) -> tuple[BoardGroup, bool]:
        self.parent.setdefault(group, group)
        self.flip.setdefault(group, False)
        if self.parent[group] is group:
            return group, False
        root, flipped = self.find(self.parent[group])
        self.parent[group], self.flip[group] = root, self.flip[group] ^ flipped
        return root, self.flip[group]

    def link(self, a: BoardGroup, b: BoardGroup, b_reversed: bool) -> None:
        root_a, flip_a = self.find(a)
        root_b, flip_b = self.find(b)
        if root_a is not root_b:
            self.parent[root_b], self.flip[root_b] = root_a, flip_a ^ flip_b ^ b_reversed

    def boards(self, groups: list[BoardGroup]) -> list[list[Observation]]:
        """Every physical board's sightings, each in the corner order of its board's root."""
        found: dict[BoardGroup, list[Observation]] = {}
        for group in groups:
            root, flipped = self.find(group)
            found.setdefault(root, []).extend(m.reversed() if flipped else m for m in group.members)
        return [sightings for sightings in found.values() if len(sightings) > 1]


def bundle_adjust(
    groups: list[BoardGroup],
    links: list[tuple[BoardGroup, BoardGroup, bool]],
    initial: dict[int, Matrix4],
    T_step: Matrix4,
    reference: int,
) -> BundleResult:
    """Refine ``initial`` (T_reference_station) and the view step ``T_step`` together."""
    union = _Boards()
    for a, b, b_reversed in links:
        union.link(a, b, b_reversed)
    boards = union.boards([g for g in groups if g.station in initial])
    free = sorted(s for s in initial if s != reference)
    index = {s: 6 + 6 * i for i, s in enumerate(free)}

    def unpack(x: NDArray[np.float64]) -> tuple[Matrix4, dict[int, Matrix4]]:
        poses = {reference: np.eye(4)}
        for station, i in index.items():
            poses[station] = _pose(x[i : i + 6])
        return _pose(x[:6]), poses

    def residuals(x: NDArray[np.float64]) -> NDArray[np.float64]:
        step, poses = unpack(x)
        return np.concatenate([_board_residuals(board, step, poses) for board in boards])

    x0 = np.concatenate([_params(T_step), *(_params(initial[s]) for s in free)])
    solution = least_squares(residuals, x0, loss="soft_l1", f_scale=ROBUST_SIGMAS, x_scale="jac")
    step, poses = unpack(solution.x)
    distances = _distances(boards, step, poses)
    return BundleResult(
        poses, step, float(np.sqrt(np.mean(distances**2))), len(boards), sum(len(b) for b in boards)
    )


def _board_residuals(
    board: list[Observation], step: Matrix4, poses: dict[int, Matrix4]
) -> NDArray[np.float64]:
    """Each sighting against the board's best one, in standard deviations of the pair."""
    anchor = max(board, key=lambda o: int(o.corners.valid.sum()))
    anchor_points = _in_reference(anchor, step, poses)
    parts = []
    for sighting in board:
        if sighting is anchor:
            continue
        both = sighting.corners.valid & anchor.corners.valid
        w_s, w_a = sighting.corners.weights[both], anchor.corners.weights[both]
        inverse_sigma = np.sqrt(w_s * w_a / (w_s + w_a))
        difference = _in_reference(sighting, step, poses)[both] - anchor_points[both]
        parts.append((difference * inverse_sigma[:, None]).ravel())
    return np.concatenate(parts) if parts else np.zeros(0)


def _distances(
    boards: list[list[Observation]], step: Matrix4, poses: dict[int, Matrix4]
) -> NDArray[np.float64]:
    found = []
    for board in boards:
        anchor = max(board, key=lambda o: int(o.corners.valid.sum()))
        anchor_points = _in_reference(anchor, step, poses)
        for sighting in board:
            both = sighting.corners.valid & anchor.corners.valid
            if sighting is not anchor:
                delta = _in_reference(sighting, step, poses)[both] - anchor_points[both]
                found.append(np.linalg.norm(delta, axis=1))
    return np.concatenate(found) if found else np.zeros(1)


def _in_reference(
    sighting: Observation, step: Matrix4, poses: dict[int, Matrix4]
) -> NDArray[np.float64]:
    T = poses[sighting.capture.station] @ np.linalg.matrix_power(step, sighting.capture.view)
    return transform_points(T, sighting.corners.points_m)


def _pose(x: NDArray[np.float64]) -> Matrix4:
    return make_transform(Rotation.from_rotvec(x[:3]).as_matrix(), x[3:6])


def _params(T: Matrix4) -> NDArray[np.float64]:
    return np.concatenate([Rotation.from_matrix(T[:3, :3]).as_rotvec(), T[:3, 3]])
