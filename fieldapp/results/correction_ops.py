"""The corrections replayed on a plot's point labels: merge, split (by geodesic distance from
the picked stems, as the reconstruction splits touching plants), delete, renumber; the plants
touched are measured again at the end."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from fieldapp.recon.geodesic import UNREACHED
from fieldapp.recon.plants import assign_by_settings
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.correction_plot import PlotState, measure_again
from fieldapp.results.corrections import Delete, Merge, PlantRef, Relabel, Split

AnyOperation = Merge | Split | Delete | Relabel

MATCH_M = 0.08
"""A plant is found again when its centroid is this close (plan view) to the recorded one."""
STEM_SNAP_M = 0.05
"""A picked stem is moved onto the plant's nearest point (plan view) when it is this close."""


class Unmatched(Exception):
    """An operation that cannot be applied to this plot; the text says why."""


def replay(
    state: PlotState,
    operations: list[AnyOperation],
    settings: ReconstructionSettings,
    match_m: float = MATCH_M,
) -> dict[int, str]:
    """Apply ``operations`` in order to ``state``, then measure the plants they touched;
    returns, by operation index, why each one that could not be applied was skipped."""
    problems: dict[int, str] = {}
    for index, operation in enumerate(operations):
        try:
            _apply(state, operation, settings, match_m)
        except Unmatched as why:
            problems[index] = str(why)
    for plant in sorted(state.dirty):
        if state.members(plant).size:
            measure_again(state, plant, settings)
    state.dirty.clear()
    return problems


def _apply(
    state: PlotState, operation: AnyOperation, settings: ReconstructionSettings, match_m: float
) -> None:
    if isinstance(operation, Merge):
        ids = find_plants(state, operation.plants, match_m)
        into = ids[[p.plant for p in operation.plants].index(operation.into)]
        state.labels.plant_id[np.isin(state.labels.plant_id, ids)] = into
        for plant in ids:
            if plant != into:
                _forget(state, plant)
        _touched(state, into)
    elif isinstance(operation, Split):
        (plant,) = find_plants(state, [operation.plant], match_m)
        _split(state, plant, operation, settings)
    elif isinstance(operation, Delete):
        (plant,) = find_plants(state, [operation.plant], match_m)
        index = state.members(plant)
        state.labels.plant_id[index] = 0
        state.labels.organ[index] = 0
        state.labels.leaf_id[index] = 0
        _forget(state, plant)
    else:
        (plant,) = find_plants(state, [operation.plant], match_m)
        _renumber(state, plant, operation.into)


def find_plants(state: PlotState, refs: list[PlantRef], match_m: float) -> list[int]:
    """The plant each of ``refs`` is in this plot: the one with its id when its centroid is
    within ``match_m`` of the recorded one, else the nearest within ``match_m``; each plant
    once. Raises :class:`Unmatched`."""
    centroids = state.centroids_xy_m()
    ids = np.array(sorted(centroids), dtype=np.int64)
    xy = np.array([centroids[i] for i in ids]).reshape(-1, 2)
    found: list[int] = []
    for ref in refs:
        wanted = np.asarray(ref.xy_m)
        if (
            ref.plant in centroids
            and ref.plant not in found
            and np.linalg.norm(centroids[ref.plant] - wanted) <= match_m
        ):
            found.append(ref.plant)
            continue
        distance = np.linalg.norm(xy - wanted, axis=1) if len(xy) else np.zeros(0)
        free = [k for k in np.argsort(distance) if int(ids[k]) not in found]
        if not free or distance[free[0]] > match_m:
            x, y = ref.xy_m
            raise Unmatched(
                f"no plant within {100 * match_m:.0f} cm of plant {ref.plant}'s place "
                f"({x:.3f}, {y:.3f}) m"
            )
        found.append(int(ids[free[0]]))
    return found


def _split(
    state: PlotState, plant: int, operation: Split, settings: ReconstructionSettings
) -> None:
    index = state.members(plant)
    stems = _snapped(state.cloud.points[index], operation.stems_xy_m, plant)
    part = stem_parts(state.cloud.points[index], stems, settings)
    taken = set(state.rows) | set(state.centroids_xy_m())
    numbers = [plant]
    for wanted in operation.into[1:]:
        number = wanted if wanted not in taken and wanted not in numbers else None
        numbers.append(number or max(taken | set(numbers)) + 1)
    for k, number in enumerate(numbers):
        state.labels.plant_id[index[part == k]] = number
        _touched(state, number)


def _snapped(
    points_m: NDArray[np.float64], stems_xy_m: list[tuple[float, float]], plant: int
) -> NDArray[np.float64]:
    """(S, 2) the picked stems, each moved onto the plant's nearest point in plan view."""
    tree = cKDTree(points_m[:, :2])
    distance, nearest = tree.query(np.asarray(stems_xy_m, np.float64))
    for (x, y), d in zip(stems_xy_m, distance, strict=True):
        if d > STEM_SNAP_M:
            raise Unmatched(
                f"the stem picked at ({x:.3f}, {y:.3f}) m is {100 * d:.0f} cm from plant {plant}"
            )
    return points_m[nearest, :2]


def stem_parts(
    points_m: NDArray[np.float64], stems_xy_m: NDArray[np.float64], settings: ReconstructionSettings
) -> NDArray[np.intp]:
    """(N,) the stem (index into ``stems_xy_m`` (S, 2)) each point of a plant (N, 3) is nearest
    to along the plant (:func:`fieldapp.recon.geodesic.assign_to_stems`, the reconstruction's
    settings); a point no stem reaches goes with its nearest reached point. Raises
    :class:`Unmatched` when a stem ends up with no point."""
    assignment = assign_by_settings(points_m, stems_xy_m, settings.plants.stems)
    part = assignment.stem.copy()
    reached = part != UNREACHED
    if not reached.any():
        raise Unmatched("no picked stem reaches the plant's points")
    if not reached.all():
        _, nearest = cKDTree(points_m[reached]).query(points_m[~reached])
        part[~reached] = part[reached][nearest]
    empty = [k for k in range(len(stems_xy_m)) if not (part == k).any()]
    if empty:
        x, y = stems_xy_m[empty[0]]
        raise Unmatched(f"the stem at ({x:.3f}, {y:.3f}) m gets no point of its own")
    return part


def _renumber(state: PlotState, plant: int, into: int) -> None:
    if into == plant:
        return
    if into in state.rows or (state.labels.plant_id == into).any():
        raise Unmatched(f"plant number {into} is taken by another plant")
    state.labels.plant_id[state.labels.plant_id == plant] = into
    row = state.rows.pop(plant, None)
    if row is not None:
        state.rows[into] = replace(row, plant=into)
    leaves = state.leaves.pop(plant, None)
    if leaves is not None:
        state.leaves[into] = [replace(leaf, plant_id=into) for leaf in leaves]
    for marks in (state.dirty, state.corrected):
        if plant in marks:
            marks.discard(plant)
            marks.add(into)
    state.corrected.add(into)


def _touched(state: PlotState, plant: int) -> None:
    state.dirty.add(plant)
    state.corrected.add(plant)


def _forget(state: PlotState, plant: int) -> None:
    state.rows.pop(plant, None)
    state.leaves.pop(plant, None)
    state.dirty.discard(plant)
    state.corrected.discard(plant)
