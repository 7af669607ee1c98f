"""Where the plants of a scene touch: the truth of a plot whose canopies overlap.

Two plants **touch** when some point of one's surface lies within :data:`TOUCH_DISTANCE_M` of
the other's; a plant **reaches into** a neighbour's space when some of its surface lies nearer
to the neighbour's stem than to its own (past the bisector between the two stems, in plan
view). Surfaces are compared through :data:`SAMPLES_PER_PLANT` points sampled uniformly on each
mesh (about 5 mm apart on a 1.2 m plant).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from numpy.typing import NDArray
from scipy.spatial import cKDTree

TOUCH_DISTANCE_M = 0.01
SAMPLES_PER_PLANT = 20_000
NEIGHBOUR_RANGE_M = 2.0
"""Plants farther apart than this (stem to stem) are not compared."""


@dataclass(frozen=True)
class PlantSurface:
    """One plant's mesh ((V, 3) vertices, (T, 3) triangles, field frame) and stem foot (3,)."""

    name: str
    vertices_m: NDArray[np.float64]
    triangles: NDArray[np.int32]
    base_m: NDArray[np.float64]


@dataclass(frozen=True)
class CanopyContacts:
    """Per plant name, the names of the plants it touches and of those it reaches into."""

    touching: dict[str, list[str]]
    reaching_into: dict[str, list[str]]

    @property
    def touching_pairs(self) -> int:
        return sum(len(v) for v in self.touching.values()) // 2


def surface_samples_m(surface: PlantSurface, seed: int = 0) -> NDArray[np.float64]:
    """(SAMPLES_PER_PLANT, 3) points spread uniformly over the plant's surface."""
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(surface.vertices_m),
        o3d.utility.Vector3iVector(surface.triangles.astype(np.int32)),
    )
    o3d.utility.random.seed(seed)
    return np.asarray(mesh.sample_points_uniformly(SAMPLES_PER_PLANT).points)


def _touch(a: NDArray[np.float64], b: NDArray[np.float64], tree_b: cKDTree) -> bool:
    """Whether some point of ``a`` (N, 3) lies within :data:`TOUCH_DISTANCE_M` of ``b``."""
    low = b.min(axis=0) - TOUCH_DISTANCE_M
    high = b.max(axis=0) + TOUCH_DISTANCE_M
    inside = a[np.all((a >= low) & (a <= high), axis=1)]
    if len(inside) == 0:
        return False
    distance, _ = tree_b.query(inside, distance_upper_bound=TOUCH_DISTANCE_M)
    return bool(np.isfinite(distance).any())


def canopy_contacts(plants: list[PlantSurface], seed: int = 0) -> CanopyContacts:
    """Which plants touch and which reach into a neighbour's space."""
    samples = [surface_samples_m(p, seed) for p in plants]
    trees = [cKDTree(s) for s in samples]
    touching: dict[str, list[str]] = {p.name: [] for p in plants}
    reaching: dict[str, list[str]] = {p.name: [] for p in plants}
    for i, a in enumerate(plants):
        for j, b in enumerate(plants):
            if i == j or np.linalg.norm(a.base_m[:2] - b.base_m[:2]) > NEIGHBOUR_RANGE_M:
                continue
            own = np.linalg.norm(samples[i][:, :2] - a.base_m[:2], axis=1)
            other = np.linalg.norm(samples[i][:, :2] - b.base_m[:2], axis=1)
            if np.any(other < own):
                reaching[a.name].append(b.name)
            if j > i and _touch(samples[i], samples[j], trees[j]):
                touching[a.name].append(b.name)
                touching[b.name].append(a.name)
    return CanopyContacts(touching, reaching)
