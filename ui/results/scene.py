"""What the 3D view and the map draw, as plain arrays: a subsample of the global cloud with
colours, which plant each point belongs to (as the results folder says, exactly), the plant
labels and the ground grid's extent; and the screen-space geometry of picking in the views."""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ui.results.data import PlotResults

MAX_POINTS = 150_000
"""The 3D view and the map draw at most this many points (a plot has a few hundred thousand)."""
DIM = 0.35
"""Brightness of the other plants' points while one plant is selected."""
HIGHLIGHT = np.array([1.0, 0.25, 0.1, 1.0], np.float32)
PICK_PX = 6.0
"""A click picks a point drawn at most this far from it (widget pixels)."""
FRONT_M = 0.03
"""Of the points under a click, those this close to the nearest one (along the view) are the
ones in front: a click picks among them, not a point seen through a gap behind them."""


@dataclass(frozen=True)
class Label:
    plant: int
    position_m: NDArray[np.float64]
    """(3,) above the plant's base, at its top (field frame)."""
    radius_m: float


@dataclass(frozen=True)
class CloudScene:
    points_m: NDArray[np.float32]
    """(N, 3) field frame."""
    colors: NDArray[np.float32]
    """(N, 4) RGBA in 0-1."""
    plant_of_point: NDArray[np.int32]
    """(N,) plant id of each point, 0 for none."""
    labels: list[Label]
    extent_m: tuple[float, float, float, float]
    """(x_min, x_max, y_min, y_max) of the plot, for the ground grid."""

    def colors_for(self, selected: int | Collection[int] | None) -> NDArray[np.float32]:
        """(N, 4) colours with the points of ``selected`` (a plant or several) highlighted and
        the others dimmed."""
        plants = [selected] if isinstance(selected, int) else list(selected or [])
        if not plants:
            return self.colors
        colors = self.colors.copy()
        colors[:, :3] *= DIM
        mine = np.isin(self.plant_of_point, plants)
        colors[mine] = 0.5 * self.colors[mine] + 0.5 * HIGHLIGHT
        return colors

    def label(self, plant: int) -> Label:
        for label in self.labels:
            if label.plant == plant:
                return label
        raise KeyError(plant)


def build_scene(results: PlotResults, max_points: int = MAX_POINTS, seed: int = 0) -> CloudScene:
    """The scene of ``results``: at most ``max_points`` points, drawn at random."""
    points, colors = results.cloud.points, results.cloud.colors
    plants = results.plant_of_point()
    if len(points) > max_points:
        chosen = np.sort(np.random.default_rng(seed).choice(len(points), max_points, False))
        points, colors, plants = points[chosen], colors[chosen], plants[chosen]
    rgba = np.ones((len(points), 4), np.float32)
    rgba[:, :3] = colors.astype(np.float32) / 255.0
    labels = [Label(p.plant, results.top_m(p.plant), p.width_cm / 200.0) for p in results.plants]
    return CloudScene(
        points.astype(np.float32),
        rgba,
        plants.astype(np.int32),
        labels,
        _extent(points, labels),
    )


def nearest_plant(
    xy_m: tuple[float, float], labels: list[Label], max_distance_m: float = 0.3
) -> int | None:
    """The plant whose base is nearest ``xy_m`` (within its radius or ``max_distance_m``)."""
    if not labels:
        return None
    distances = [
        float(np.hypot(xy_m[0] - lab.position_m[0], xy_m[1] - lab.position_m[1])) for lab in labels
    ]
    index = int(np.argmin(distances))
    if distances[index] > max(labels[index].radius_m, max_distance_m):
        return None
    return labels[index].plant


def nearest_on_screen(
    screen_xy: tuple[float, float], projected: list[tuple[int, float, float]], max_px: float = 40.0
) -> int | None:
    """The plant whose projected label (plant, x_px, y_px) is nearest a click, within ``max_px``."""
    best, found = max_px, None
    for plant, x, y in projected:
        distance = float(np.hypot(screen_xy[0] - x, screen_xy[1] - y))
        if distance <= best:
            best, found = distance, plant
    return found


def project(
    points_m: NDArray[np.float64], mvp: NDArray[np.float64], width_px: int, height_px: int
) -> NDArray[np.float64]:
    """(N, 2) pixel positions (origin top-left) of ``points_m`` (N, 3) through the 4 x 4
    model-view-projection matrix ``mvp`` (OpenGL clip space); NaN behind the camera."""
    homogeneous = np.c_[points_m, np.ones(len(points_m))] @ mvp.T
    w = homogeneous[:, 3:4]
    ndc = np.where(w > 1e-9, homogeneous[:, :3] / np.where(w > 1e-9, w, 1.0), np.nan)
    pixels: NDArray[np.float64] = np.c_[
        (ndc[:, 0] + 1) / 2 * width_px, (1 - ndc[:, 1]) / 2 * height_px
    ]
    return pixels


def depth_m(points_m: NDArray[np.float64], mvp: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) distance of ``points_m`` (N, 3) in front of the camera along its axis (the clip
    space w of a perspective ``mvp``; metres for a view in metres)."""
    depth: NDArray[np.float64] = np.c_[points_m, np.ones(len(points_m))] @ mvp[3]
    return depth


def pick_on_screen(
    screen_xy: tuple[float, float],
    pixels: NDArray[np.float64],
    depth: NDArray[np.float64] | None = None,
    max_px: float = PICK_PX,
) -> int | None:
    """The index of the point a click at ``screen_xy`` picks, of points drawn at ``pixels``
    (N, 2; NaN: not drawn): the nearest on screen within ``max_px``, taken among the front
    ones (within :data:`FRONT_M` of the nearest ``depth`` (N,), when given) so that the click
    picks what the ray from the camera through it meets first; None when none is that close."""
    if len(pixels) == 0:
        return None
    distance_px = np.hypot(pixels[:, 0] - screen_xy[0], pixels[:, 1] - screen_xy[1])
    near = np.flatnonzero(np.nan_to_num(distance_px, nan=np.inf) <= max_px)
    if len(near) == 0:
        return None
    if depth is not None:
        near = near[depth[near] <= depth[near].min() + FRONT_M]
    return int(near[np.argmin(distance_px[near])])


def _extent(points: NDArray[np.float64], labels: list[Label]) -> tuple[float, float, float, float]:
    xy = np.vstack([points[:, :2], *[lab.position_m[None, :2] for lab in labels], np.zeros((1, 2))])
    low, high = xy.min(axis=0) - 0.2, xy.max(axis=0) + 0.2
    return float(low[0]), float(high[0]), float(low[1]), float(high[1])
