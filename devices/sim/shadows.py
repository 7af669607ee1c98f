"""Where on the ground a shadow can fall: a coarse map that spares most shadow rays.

Only bodies standing on the soil (plants, spheres, boards) cast shadows worth drawing; a soil
point farther than their shadows reach is lit (the soil's own few cm of relief cast none at a
sun 50 degrees up). The map marks the cells under every caster's shadow, so the renderer casts
shadow rays only for soil points in marked cells and for points on the casters themselves.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from devices.sim.scene import Scene

CELL_M = 0.05
STEPS = 16


class ShadowMap:
    """A boolean grid over the soil's extent: True where some caster's shadow may fall.

    ``sun``: (3,) unit vector towards the sun, field frame."""

    def __init__(self, scene: Scene, sun: NDArray[np.float32]) -> None:
        self._half_m = scene.soil.spec.half_extent_m if scene.soil else 0.0
        cells = max(1, int(np.ceil(2 * self._half_m / CELL_M)))
        self._grid = np.zeros((cells, cells), bool)
        self.is_soil = np.array([body.kind == "soil" for body in scene.bodies], bool)
        self._mapped = scene.soil is not None and sun[2] > 0
        casters = [
            _surface_points(b.vertices_m, b.triangles) for b in scene.bodies if b.kind != "soil"
        ]
        if scene.soil is None or not casters or sun[2] <= 0:
            return
        points = np.concatenate(casters)
        height = points[:, 2] - scene.soil.height_m(points[:, 0], points[:, 1])
        reach = np.clip(height, 0.0, None)[:, None] * (-sun[:2] / sun[2])[None, :]
        for fraction in np.linspace(0.0, 1.05, STEPS):
            self._mark(points[:, :2] + fraction * reach)
        grown = self._grid.copy()  # one cell of slack all round
        for axis in (0, 1):
            for shift in (1, -1):
                grown |= np.roll(self._grid, shift, axis=axis)
        self._grid = grown

    def _mark(self, xy_m: NDArray[np.float64]) -> None:
        self._grid.reshape(-1)[self._cells(xy_m)[1]] = True  # a view: the grid is contiguous

    def _cells(
        self, xy_m: NDArray[np.floating], among: NDArray[np.bool_] | bool = True
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Which of ``xy_m`` (N, 2 or more), of those ``among`` (N,), lie over the grid
        (indices), and their cells (flat indices into it). The cell coordinates stay floats
        until then: within [0, n) exactly where their floor is a cell."""
        n = self._grid.shape[0]
        u = (xy_m[:, 0] + self._half_m) / CELL_M
        v = (xy_m[:, 1] + self._half_m) / CELL_M
        over = np.flatnonzero(among & (u >= 0) & (u < n) & (v >= 0) & (v < n))
        return over, v[over].astype(np.intp) * n + u[over].astype(np.intp)

    def may_be_shadowed(
        self, points_m: NDArray[np.floating], body: NDArray[np.int64]
    ) -> NDArray[np.bool_]:
        """For hits at ``points_m`` (N, 3) on bodies ``body`` (N,): whether to cast a shadow
        ray (always on casters, on soil only where a shadow may fall; everywhere when the
        scene has no :class:`~devices.sim.soil.Soil` to map)."""
        if not self._mapped:
            return np.ones(len(body), bool)
        result = ~self.is_soil[body]
        on_soil, cell = self._cells(points_m, ~result)
        result[on_soil] = self._grid.reshape(-1)[cell]
        return result


def _surface_points(
    vertices_m: NDArray[np.float64], triangles: NDArray[np.int32]
) -> NDArray[np.float64]:
    """(N, 3) the vertices plus points spread over every triangle larger than a cell, so a big
    flat caster (a board) marks all of its shadow, not only its corners' lines."""
    corners = vertices_m[triangles]
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    points = [vertices_m]
    for n in np.unique(np.ceil(edges / (CELL_M / 2)).astype(int)):
        if n <= 1:
            continue
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
        keep = i + j <= n
        weights = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], axis=1) / n
        for triangle in corners[np.ceil(edges / (CELL_M / 2)).astype(int) == n]:
            points.append(weights @ triangle)
    return np.concatenate(points)
