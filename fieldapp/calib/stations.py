"""Station-to-station calibration: boards between neighbouring stations, each seen from both,
give pairwise transforms, composed along a spanning tree into ``stations.to_reference``."""

from __future__ import annotations

import heapq
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from devices.geometry import Matrix4, invert, transform_points
from fieldapp.calib.board import Board
from fieldapp.calib.observe import Observation, depth_problem, observe, paired_points
from fieldapp.calib.rigid import RigidFit, fit_rigid_weighted
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import ViewStep
from fieldapp.io.session import Session

MAX_PAIR_RMSE_M = 0.02
ORDER_CONFIDENCE = 3.0


@dataclass
class PairResult:
    station_a: int
    station_b: int
    targets: list[str]
    fit: RigidFit
    """``fit.T_target_source`` maps station b's view 0 into station a's view 0."""


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
    corners = observation.corners
    moved = type(corners)(transform_points(T, corners.points_m), corners.weights)
    return Observation(
        observation.capture, observation.corners_px, observation.corner_zero_dark, moved
    )


def best_observations(
    session: Session, board: Board, view_step: ViewStep
) -> dict[str, dict[int, Observation]]:
    """target -> station -> the observation (in view 0's frame) with the most lifted corners."""
    found: dict[str, dict[int, Observation]] = defaultdict(dict)
    for capture in session.captures:
        target = capture.key[2]
        if target is None:
            continue
        observation = observe(session, capture, board)
        if observation is None or depth_problem(observation):
            continue
        current = found[target].get(capture.station)
        if current is None or observation.lifted_fraction > current.lifted_fraction:
            found[target][capture.station] = in_view0(observation, view_step)
    return found


def fit_pair(a: Observation, b: Observation) -> tuple[RigidFit, Observation]:
    """Fit b -> a, trying b's corner order both ways (a board seen from two stations is often
    detected half-turned); the better order must win clearly. Returns the fit and b in the
    order that won."""
    candidates = [
        (fit_rigid_weighted(*paired_points(a, order)), order) for order in (b, b.reversed())
    ]
    (best, best_b), (other, _) = sorted(candidates, key=lambda c: c[0].rmse_m)
    if other.rmse_m < ORDER_CONFIDENCE * best.rmse_m:
        raise FieldappError(
            f"cannot tell the corner order of the board seen from {a.name} and {b.name}: use "
            "a board whose inner corner counts differ by an odd number (e.g. 9 x 6)"
        )
    return best, best_b


def pairwise(observations: dict[str, dict[int, Observation]]) -> list[PairResult]:
    """One fit per pair of stations, over every board both of them saw."""
    matches: dict[tuple[int, int], list[tuple[str, Observation, Observation]]] = defaultdict(list)
    for target, by_station in observations.items():
        stations = sorted(by_station)
        for i, a in enumerate(stations):
            for b in stations[i + 1 :]:
                _, ordered_b = fit_pair(by_station[a], by_station[b])
                matches[(a, b)].append((target, by_station[a], ordered_b))
    results = []
    for (a, b), seen in sorted(matches.items()):
        sources, targets, weights = zip(
            *(paired_points(obs_a, obs_b) for _, obs_a, obs_b in seen), strict=True
        )
        joint = fit_rigid_weighted(np.vstack(sources), np.vstack(targets), np.concatenate(weights))
        results.append(PairResult(a, b, [target for target, _, _ in seen], joint))
    return results


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


def calibrate_stations(
    session: Session, board: Board, view_step: ViewStep, reference: int = 5
) -> StationsResult:
    """``T_reference_station`` for every station linked to ``reference`` through boards."""
    observations = best_observations(session, board, view_step)
    if not observations:
        raise FieldappError(
            "no capture tagged with a target shows the board: tag the captures of each board "
            'with "target": "<board name>" in session.json'
        )
    pairs = pairwise(observations)
    stations = {c.station for c in session.captures}
    if not pairs:
        raise FieldappError(
            "no board was seen from two stations: place each board between "
            "two neighbouring stations where both see it whole"
        )
    tree = spanning_tree(pairs, reference)
    unlinked = sorted(stations - set(tree) - {reference})
    if reference not in stations and not tree:
        raise FieldappError(f"the reference station {reference} sees no board")
    if unlinked:
        raise FieldappError(
            f"stations {', '.join(map(str, unlinked))} are not linked to "
            f"station {reference} by any board seen from both sides"
        )
    T_reference: dict[int, Matrix4] = {reference: np.eye(4)}

    def resolve(station: int) -> Matrix4:
        if station not in T_reference:
            parent, T_parent_station = tree[station]
            T_reference[station] = resolve(parent) @ T_parent_station
        return T_reference[station]

    for station in tree:
        resolve(station)
    result = StationsResult(reference, T_reference, pairs, {s: p for s, (p, _) in tree.items()})
    for pair in pairs:
        if pair.fit.rmse_m > MAX_PAIR_RMSE_M:
            result.warnings.append(
                f"stations {pair.station_a}-{pair.station_b}: residual "
                f"{1000 * pair.fit.rmse_m:.1f} mm is high: the board may have moved between "
                "the two stations' captures"
            )
    return result
