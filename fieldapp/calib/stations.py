"""Station-to-station calibration: boards between neighbouring stations, each seen from both,
give pairwise transforms, composed along a spanning tree into ``stations.to_reference`` and
then refined jointly over every corner seen from two stations.

Several boards may stand in the plot at once. Each station's sightings are grouped by position
(in its view-0 frame), and the sightings of two stations are matched through the station
transforms in force (the nominal ones: a base stops within centimetres of them). Without such a
prior, captures must show one board each and their ``target`` tags say which.
"""

from __future__ import annotations

import heapq
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from devices.geometry import Matrix4, invert, make_transform, pose_error, transform_points
from fieldapp.calib.board import Board
from fieldapp.calib.observe import (
    Observation,
    align_order,
    depth_problem,
    observe_all,
    paired_points,
)
from fieldapp.calib.rigid import RigidFit, fit_rigid_weighted
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import ViewStep
from fieldapp.io.session import Session

SAME_BOARD_M = 0.15
"""Sightings of one station closer than this (in its own frame) are the same board."""
MATCH_M = 0.4
"""Sightings of two stations closer than this after the prior are the same board: a base stops
a few cm and 1-2 degrees off, which at 2 m moves a board by up to ~0.3 m."""
MAX_PAIR_RMSE_M = 0.01
MAX_PRIOR_DISTANCE_M = 0.4
MAX_PRIOR_ROTATION_DEG = 10.0
"""How far a pair may lie from the calibration in force."""

Match = tuple[str, Observation, Observation]


@dataclass
class PairResult:
    station_a: int
    station_b: int
    boards: list[str]
    fit: RigidFit
    """``fit.T_target_source`` maps station b's view 0 into station a's view 0."""
    points_b: NDArray[np.float64]
    points_a: NDArray[np.float64]
    weights: NDArray[np.float64]
    """The corner correspondences behind the fit: (N, 3), (N, 3), (N,)."""


@dataclass
class StationsResult:
    reference: int
    T_reference_station: dict[int, Matrix4]
    pairs: list[PairResult]
    tree: dict[int, int]
    """Each station's parent on the way to the reference."""
    warnings: list[str] = field(default_factory=list)


def in_view0(observation: Observation, view_step: ViewStep) -> Observation:
    """The observation's 3D corners moved from its view's frame into view 0's."""
    T = view_step.T_view0_view(observation.capture.view)
    corners = type(observation.corners)(
        transform_points(T, observation.corners.points_m), observation.corners.weights
    )
    return Observation(
        observation.capture, observation.corners_px, observation.corner_zero_dark, corners
    )


def sightings(
    session: Session, board: Board, view_step: ViewStep, use_untagged: bool
) -> dict[int, list[Observation]]:
    """station -> one observation (view-0 frame) per physical board, averaged over every
    capture of that station that saw it (noise falls as more views see a board).

    Captures tagged with a ``target`` always count; untagged ones when ``use_untagged``.
    """
    groups: dict[int, list[list[Observation]]] = defaultdict(list)
    for capture in session.captures:
        if capture.key[2] is None and not use_untagged:
            continue
        for observation in observe_all(session, capture, board):
            if depth_problem(observation) is None:
                _group(groups[capture.station], in_view0(observation, view_step), board)
    return {station: [_average(g) for g in found] for station, found in groups.items()}


def _group(groups: list[list[Observation]], new: Observation, board: Board) -> None:
    for group in groups:
        if np.linalg.norm(group[0].centroid_m - new.centroid_m) < SAME_BOARD_M:
            aligned = align_order(group[0], new, board, np.eye(4))  # same frame: no motion
            if aligned is not None:
                group.append(aligned)
            return
    groups.append([new])


def _average(group: list[Observation]) -> Observation:
    """Weighted mean of a board's corners over several sightings in one frame."""
    points = np.stack([o.corners.points_m for o in group])
    weights = np.stack([np.where(o.corners.valid, o.corners.weights, 0.0) for o in group])
    total = weights.sum(axis=0)
    mean = (
        np.einsum("kn,knd->nd", weights, np.nan_to_num(points)) / np.maximum(total, 1e-30)[:, None]
    )
    mean[total == 0] = np.nan
    first = group[0]
    return Observation(
        first.capture, first.corners_px, first.corner_zero_dark, type(first.corners)(mean, total)
    )


def matches(
    seen_a: list[Observation], seen_b: list[Observation], T_prior: Matrix4 | None
) -> list[Match]:
    """Pairs of sightings of the same board from two stations."""
    if T_prior is None:  # tags decide, when a tag names a single sighting on each side
        tags_a, tags_b = _single_tags(seen_a), _single_tags(seen_b)
        return [(tag, tags_a[tag], tags_b[tag]) for tag in sorted(tags_a.keys() & tags_b.keys())]
    found = []
    for b in seen_b:
        moved = T_prior[:3, :3] @ b.centroid_m + T_prior[:3, 3]
        distances = [float(np.linalg.norm(a.centroid_m - moved)) for a in seen_a]
        if distances and min(distances) < MATCH_M:
            a = seen_a[int(np.argmin(distances))]
            label = _tag(a) or "board at " + " ".join(f"{x:+.2f}" for x in a.centroid_m)
            found.append((label, a, b))
    return found


def _tag(observation: Observation) -> str:
    return observation.capture.key[2] or ""


def _single_tags(seen: list[Observation]) -> dict[str, Observation]:
    """tag -> its sighting, for tags whose captures showed exactly one board."""
    counts: dict[str, list[Observation]] = defaultdict(list)
    for observation in seen:
        if _tag(observation):
            counts[_tag(observation)].append(observation)
    return {tag: found[0] for tag, found in counts.items() if len(found) == 1}


def fit_pair(
    a: int, b: int, found: list[Match], board: Board, T_prior: Matrix4 | None
) -> tuple[PairResult | None, list[str]]:
    """One joint fit over every board both stations saw, or None with the reasons."""
    used, refused = [], []
    for label, obs_a, obs_b in found:
        ordered_b = align_order(obs_a, obs_b, board, T_prior)
        if ordered_b is None:
            refused.append(f"stations {a}-{b} via {label}: corner order cannot be told")
            continue
        why = _implausible(fit_rigid_weighted(*paired_points(obs_a, ordered_b)), T_prior)
        if why:
            refused.append(f"stations {a}-{b} via {label}: {why}")
            continue
        used.append((label, obs_a, ordered_b))
    if not used:
        return None, refused
    sources, targets, weights = zip(*(paired_points(oa, ob) for _, oa, ob in used), strict=True)
    joint = fit_rigid_weighted(np.vstack(sources), np.vstack(targets), np.concatenate(weights))
    labels = [label for label, _, _ in used]
    if joint.rmse_m > MAX_PAIR_RMSE_M:
        refused.append(
            f"stations {a}-{b}: the boards {', '.join(labels)} disagree (joint RMSE "
            f"{1000 * joint.rmse_m:.0f} mm): a board moved, or tags name different boards"
        )
        return None, refused
    return PairResult(
        a, b, labels, joint, np.vstack(sources), np.vstack(targets), np.concatenate(weights)
    ), refused


def _implausible(fit: RigidFit, T_prior: Matrix4 | None) -> str | None:
    if fit.rmse_m > MAX_PAIR_RMSE_M:
        return f"RMSE {1000 * fit.rmse_m:.1f} mm (board moved between the captures?)"
    if T_prior is not None:
        moved_m, turned_deg = pose_error(fit.T_target_source, T_prior)
        if moved_m > MAX_PRIOR_DISTANCE_M or turned_deg > MAX_PRIOR_ROTATION_DEG:
            return (
                f"{100 * moved_m:.0f} cm and {turned_deg:.1f} degrees from the calibration in "
                "force (another board matched?)"
            )
    return None


def spanning_tree(pairs: list[PairResult], reference: int) -> dict[int, tuple[int, Matrix4]]:
    """station -> (parent, T_parent_station), by the smallest summed pair RMSE (Dijkstra)."""
    edges: dict[int, list[tuple[float, int, Matrix4]]] = defaultdict(list)
    for pair in pairs:
        T_a_b = pair.fit.T_target_source
        edges[pair.station_a].append((pair.fit.rmse_m, pair.station_b, T_a_b))
        edges[pair.station_b].append((pair.fit.rmse_m, pair.station_a, invert(T_a_b)))
    tree: dict[int, tuple[int, Matrix4]] = {}
    done = {reference}
    queue = [(cost, reference, s, T) for cost, s, T in edges[reference]]
    heapq.heapify(queue)
    while queue:
        cost, parent, station, T_parent_station = heapq.heappop(queue)
        if station in done:
            continue
        done.add(station)
        tree[station] = (parent, T_parent_station)
        for step, nxt, T in edges[station]:
            if nxt not in done:
                heapq.heappush(queue, (cost + step, station, nxt, T))
    return tree


def compose(tree: dict[int, tuple[int, Matrix4]], reference: int) -> dict[int, Matrix4]:
    """``T_reference_station`` for the reference and every station in the tree."""
    T_reference: dict[int, Matrix4] = {reference: np.eye(4)}

    def resolve(station: int) -> Matrix4:
        if station not in T_reference:
            parent, T_parent_station = tree[station]
            T_reference[station] = resolve(parent) @ T_parent_station
        return T_reference[station]

    for station in tree:
        resolve(station)
    return T_reference


def refine_jointly(
    pairs: list[PairResult], initial: dict[int, Matrix4], reference: int
) -> dict[int, Matrix4]:
    """All station poses at once: minimise every corner pair's disagreement in the reference
    frame (robust loss), starting from the spanning tree. Errors no longer pile up along long
    chains of the tree."""
    free = sorted(s for s in initial if s != reference)
    index = {s: i for i, s in enumerate(free)}
    scale = float(np.median(np.concatenate([p.weights for p in pairs])))

    def pose(x: NDArray[np.float64], station: int) -> Matrix4:
        if station == reference:
            return np.eye(4)
        i = 6 * index[station]
        return make_transform(Rotation.from_rotvec(x[i : i + 3]).as_matrix(), x[i + 3 : i + 6])

    def residuals(x: NDArray[np.float64]) -> NDArray[np.float64]:
        parts = []
        for pair in pairs:
            in_reference_a = transform_points(pose(x, pair.station_a), pair.points_a)
            in_reference_b = transform_points(pose(x, pair.station_b), pair.points_b)
            weight = np.sqrt(pair.weights / scale)[:, None]
            parts.append(((in_reference_a - in_reference_b) * weight).ravel())
        return np.concatenate(parts)

    x0 = np.concatenate(
        [
            np.r_[Rotation.from_matrix(initial[s][:3, :3]).as_rotvec(), initial[s][:3, 3]]
            for s in free
        ]
    )
    solution = least_squares(residuals, x0, loss="soft_l1", f_scale=0.005, x_scale="jac")
    refined = {s: pose(solution.x, s) for s in free}
    refined[reference] = np.eye(4)
    return refined


def calibrate_stations(
    session: Session,
    board: Board,
    view_step: ViewStep,
    reference: int = 5,
    prior: dict[int, Matrix4] | None = None,
) -> StationsResult:
    """``T_reference_station`` for every station linked to ``reference`` through boards.

    ``prior``: the station transforms in force (e.g. nominal), to match boards between
    stations, tell the corner order when colours cannot, and drop implausible pairs.
    """
    seen = sightings(session, board, view_step, use_untagged=prior is not None)
    if not seen:
        raise FieldappError(f"no {board.cols} x {board.rows} board with usable depth was found")
    pairs, refused = [], []
    stations = sorted(seen)
    for i, a in enumerate(stations):
        for b in stations[i + 1 :]:
            T_prior = invert(prior[a]) @ prior[b] if prior and a in prior and b in prior else None
            pair, why = fit_pair(a, b, matches(seen[a], seen[b], T_prior), board, T_prior)
            refused += why
            if pair is not None:
                pairs.append(pair)
    if not pairs:
        raise FieldappError(
            "no board was seen from two stations: place each board between two neighbouring "
            "stations where both see it whole"
            + ("; pairs refused:\n  " + "\n  ".join(refused) if refused else "")
        )
    tree = spanning_tree(pairs, reference)
    unlinked = sorted({c.station for c in session.captures} - set(tree) - {reference})
    if unlinked:
        raise FieldappError(
            f"stations {', '.join(map(str, unlinked))} are not linked to station {reference} "
            "by any board seen from both sides"
        )
    result = StationsResult(
        reference,
        refine_jointly(pairs, compose(tree, reference), reference),
        pairs,
        {s: p for s, (p, _) in tree.items()},
    )
    result.warnings = [f"pair not used: {reason}" for reason in refused]
    return result
