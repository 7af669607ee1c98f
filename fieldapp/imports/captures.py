"""Grouping a folder's image files into captures and numbering their stations and views."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fieldapp.errors import FieldappError
from fieldapp.imports.names import NamedFile, natural_key

ANGLE_TOLERANCE_DEG = 0.5
"""A parsed angle may sit this far from a multiple of the step and still name its view."""


@dataclass
class PlannedCapture:
    """One capture to import: its files by kind, station, view and table angle."""

    station: int
    view: int
    angle_deg: float | None
    files: dict[str, Path] = field(default_factory=dict)


def group_files(named: list[NamedFile], lines: list[str]) -> list[dict[str, NamedFile]]:
    """Files sharing a key form one capture. When no name carries a kind token every file is a
    depth image; otherwise files without one are left out (and said so in ``lines``)."""
    if all(n.kind is None for n in named):
        return [{"depth": n} for n in named]
    groups: dict[str, dict[str, NamedFile]] = defaultdict(dict)
    for item in named:
        if item.kind is None:
            lines.append(f"{item.path}: not used: its name says neither depth, color nor ir")
        elif item.kind in groups[item.key]:
            first = groups[item.key][item.kind].path
            raise FieldappError(f"{item.path} and {first} are both the {item.kind} of one capture")
        else:
            groups[item.key][item.kind] = item
    captures = []
    for key in sorted(groups, key=natural_key):
        group = groups[key]
        if "depth" not in group:
            for item in group.values():
                lines.append(f"{item.path}: not used: no depth image with the same name")
            continue
        captures.append(group)
    return captures


def step_of(groups: list[dict[str, NamedFile]], step_deg: float | None) -> float | None:
    """The table's step: given, or the median gap between the angles the names carry."""
    if step_deg is not None:
        return step_deg
    angles = sorted({g["depth"].angle_deg for g in groups if g["depth"].angle_deg is not None})
    if len(angles) >= 2:
        return float(np.median(np.diff(angles)))
    return None


NOMINAL_STEP_DEG = 45.0
"""The step written when neither --step-deg nor the names give one (views named, or a single
capture): this project's rig; said in the import's lines."""


def plan_captures(
    groups: list[dict[str, NamedFile]], step_deg: float | None, lines: list[str]
) -> tuple[list[PlannedCapture], float]:
    """Station, view and angle of every capture; returns them with the view step (degrees).

    Views come from the names (``v3``), else from the angles divided by the step, else from
    the order of the names. Raises :class:`FieldappError` naming the files when that fails.
    """
    step = step_of(groups, step_deg)
    if step is None and len(groups) > 1 and any(g["depth"].view is None for g in groups):
        raise FieldappError(
            "the view angles are unknown: give --step-deg (the table's turn between views) or "
            "name the files with their angle (e.g. depth_045deg.png) or view (depth_v3.png)"
        )
    if step is not None and not 0.0 < abs(step) <= 180.0:
        raise FieldappError(f"view step {step:g} degrees: must be non-zero and at most 180")
    if step is None:
        step = NOMINAL_STEP_DEG
        lines.append(
            f"view step unknown: {step:g} degrees written (give --step-deg for the real one)"
        )
    order: dict[int, int] = defaultdict(int)
    planned: list[PlannedCapture] = []
    seen: dict[tuple[int, int], Path] = {}
    for group in groups:
        depth = group["depth"]
        station = depth.station if depth.station is not None else 1
        view = _view_of(depth, step, order[station])
        order[station] = view + 1
        if (station, view) in seen:
            raise FieldappError(
                f"{depth.path} and {seen[(station, view)]} are both station {station} view {view}"
            )
        seen[(station, view)] = depth.path
        angle = depth.angle_deg if depth.angle_deg is not None else view * step
        files = {kind: item.path for kind, item in group.items()}
        planned.append(PlannedCapture(station, view, angle, files))
    return sorted(planned, key=lambda c: (c.station, c.view)), step


def _view_of(depth: NamedFile, step: float, next_in_order: int) -> int:
    if depth.view is not None:
        return depth.view
    if depth.angle_deg is None:
        return next_in_order
    view = round(depth.angle_deg / step)
    if abs(view * step - depth.angle_deg) > ANGLE_TOLERANCE_DEG or view < 0:
        raise FieldappError(
            f"{depth.path}: angle {depth.angle_deg:g} degrees is not a multiple of the "
            f"{step:g}-degree step (give --step-deg, or name the view: _v3)"
        )
    return int(view)
