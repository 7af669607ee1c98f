"""Station-to-station calibration: boards between neighbouring stations, each seen from both,
give pairwise transforms, composed along a spanning tree into ``stations.to_reference``, then
refined jointly with the view step over every sighting (:mod:`fieldapp.calib.bundle`).

Several boards may stand in the plot at once. Each station's sightings are grouped by position
(:mod:`fieldapp.calib.sightings`), and two stations' boards are matched through the station
transforms in force (the nominal ones: a base stops within centimetres of them). Without such a
prior, captures must show one board each and their ``target`` tags say which.
"""

from __future__ import annotations

import heapq
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from devices.geometry import Matrix4, invert, pose_error
from fieldapp.calib.board import Board
from fieldapp.calib.bundle import BundleResult, bundle_adjust
from fieldapp.calib.observe import align_order, match_by_prior, paired_points
from fieldapp.calib.rigid import RigidFit, fit_rigid_weighted
from fieldapp.calib.sightings import BoardGroup, board_groups
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import ViewStep
from fieldapp.io.session import Session, reported_base_poses

MATCH_M = 0.4
"""Boards of two stations closer than this after the prior are the same board: a base stops
a few cm and 1-2 degrees off, which at 2 m moves a board by up to ~0.3 m."""
MAX_PAIR_RMSE_M = 0.01
MAX_PRIOR_DISTANCE_M = 0.4
MAX_PRIOR_ROTATION_DEG = 10.0
"""How far a pair may lie from the calibration in force."""

Link = tuple[BoardGroup, BoardGroup, bool]
"""Two stations' sightings of one board; True when the second's corner order is reversed."""


@dataclass
class PairResult:
    station_a: int
    station_b: int
    boards: list[str]
    fit: RigidFit
    """``fit.T_target_source`` maps station b's view 0 into station a's view 0."""
    links: list[Link]


@dataclass
class StationsResult:
    reference: int
    T_reference_station: dict[int, Matrix4]
    T_view_k_view_k1: Matrix4
    """The view step refined with the stations."""
    pairs: list[PairResult]
    tree: dict[int, int]
    """Each station's parent on the way to the reference (the starting point)."""
    bundle: BundleResult
    warnings: list[str] = field(default_factory=list)
    base_poses: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    """Where the base reported standing at each station while the boards were captured (map
    frame: x_m, y_m, yaw_deg); empty when the captures carry no ``base_pose``."""


def matches(
    seen_a: list[BoardGroup], seen_b: list[BoardGroup], T_prior: Matrix4 | None
) -> list[tuple[str, BoardGroup, BoardGroup]]:
    """Pairs of two stations' sightings of the same board."""
    if T_prior is None:  # tags decide, when a tag names a single board on each side
        tags_a, tags_b = _single_tags(seen_a), _single_tags(seen_b)
        return [(tag, tags_a[tag], tags_b[tag]) for tag in sorted(tags_a.keys() & tags_b.keys())]
    return [
        (_label(a), a, b)
        for a, b in match_by_prior(seen_a, seen_b, T_prior, MATCH_M, lambda g: g.mean.centroid_m)
    ]


def _label(group: BoardGroup) -> str:
    tags = sorted({m.capture.key[2] for m in group.members if m.capture.key[2]})
    return tags[0] if tags else "board at " + " ".join(f"{x:+.2f}" for x in group.mean.centroid_m)


def _single_tags(groups: list[BoardGroup]) -> dict[str, BoardGroup]:
    """tag -> its board, for tags that name exactly one board of the station."""
    found: dict[str, list[BoardGroup]] = defaultdict(list)
    for group in groups:
        for tag in {m.capture.key[2] for m in group.members if m.capture.key[2]}:
            found[tag].append(group)
    return {tag: groups[0] for tag, groups in found.items() if len(groups) == 1}


def fit_pair(
    a: int,
    b: int,
    found: list[tuple[str, BoardGroup, BoardGroup]],
    board: Board,
    T_prior: Matrix4 | None,
) -> tuple[PairResult | None, list[str]]:
    """One joint fit over every board both stations saw, or None with the reasons."""
    used, refused = [], []
    for label, group_a, group_b in found:
        mean_b = group_b.mean
        ordered_b = align_order(group_a.mean, mean_b, board, T_prior)
        if ordered_b is None:
            refused.append(f"stations {a}-{b} via {label}: {_unordered(board, T_prior)}")
            continue
        why = _implausible(fit_rigid_weighted(*paired_points(group_a.mean, ordered_b)), T_prior)
        if why:
            refused.append(f"stations {a}-{b} via {label}: {why}")
            continue
        used.append((label, group_a, group_b, ordered_b))
    if not used:
        return None, refused
    sources, targets, weights = zip(
        *(paired_points(ga.mean, ob) for _, ga, _, ob in used), strict=True
    )
    joint = fit_rigid_weighted(np.vstack(sources), np.vstack(targets), np.concatenate(weights))
    labels = [label for label, _, _, _ in used]
    if joint.rmse_m > MAX_PAIR_RMSE_M:
        refused.append(
            f"stations {a}-{b}: the boards {', '.join(labels)} disagree (joint RMSE "
            f"{1000 * joint.rmse_m:.0f} mm): a board moved, or tags name different boards"
        )
        return None, refused
    links = [(ga, gb, ob is not gb.mean) for _, ga, gb, ob in used]
    return PairResult(a, b, labels, joint, links), refused


def _unordered(board: Board, T_prior: Matrix4 | None) -> str:
    if board.is_symmetric and T_prior is None:
        return (
            f"the {board.cols} x {board.rows} board looks the same after a half turn and lies "
            "flat: its corner order needs the stations' nominal poses (give a calibration "
            "with stations)"
        )
    return "corner order cannot be told"


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
    seen = board_groups(session, board, view_step, use_untagged=prior is not None)
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
    groups = [g for found in seen.values() for g in found]
    links = [link for pair in pairs for link in pair.links]
    bundle = bundle_adjust(groups, links, compose(tree, reference), view_step.matrix, reference)
    result = StationsResult(
        reference,
        bundle.T_reference_station,
        bundle.T_view_k_view_k1,
        pairs,
        {s: p for s, (p, _) in tree.items()},
        bundle,
    )
    result.warnings = [f"pair not used: {reason}" for reason in refused]
    result.base_poses = {
        s: pose
        for s, pose in reported_base_poses(session).items()
        if s in result.T_reference_station
    }
    return result
