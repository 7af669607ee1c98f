"""Per-plant traits: position of the base, height above the local ground, maximum width.

- **base**: the foot of the stem: the column of points standing at the most heights in the
  plant's lower half (leaf tips droop low but lie flat), its lowest ``base_slice_m``;
- **local ground**: the median height of the soil points around the base;
- **top**, taken robustly: the highest point joined to the plant's body, from which a chain of
  plant points, each rising at most ``TOP_LINK_M`` above the next and at most
  ``TOP_LINK_ACROSS_M`` across from it, leads down ``TOP_REACH_M`` (a leaf tip sampled one
  point wide has one, and so has a thin upright tip scattered across by the sensor's lateral
  noise; a stray point or a speck of flying pixels left by the filters above the plant has
  none);
- **width**: the diameter of the smallest circle enclosing the plant's projection on the ground
  (Welzl's algorithm on the convex hull of the projection).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree

STEM_CELL_M = 0.01
"""Cell size of the column search for the stem."""

FOOT_RADIUS_M = 0.06
"""The stem's foot is looked for this close to the stem column (a thick stem's far side is
in; a leaf tip resting on the soil a leaf length away is not)."""

TOP_CANDIDATES = 200
"""Only this many of the highest points are tested as the top."""

TOP_LINK_M = 0.008
"""The longest step up of the chain that leads from the top down into the plant: 2-4 times the
points' spacing on a leaf (the last centimetre of a pointed tip is sampled a point every
5-8 mm on the simulated plots), under the 1 cm a stray point stands off the plant."""

TOP_LINK_ACROSS_M = 0.015
"""The longest step of that chain across (in plan): a thin upright top (a whorl's rolled tip,
under a pixel wide) is sampled a few points at each height, scattered across by its width and
the sensor's lateral noise (1.6-3 pixels, 7-14 mm at 1.5-2 m), while a stray point or a speck
stands *above* the plant. A step is within an ellipsoid of these two half-axes."""

TOP_REACH_M = 0.02
"""How far below the top that chain must lead: more than a speck of flying pixels is tall."""


@dataclass(frozen=True)
class PlantTraits:
    """A plant's stem base (``x_m``, ``y_m``), height above ``ground_z_m``, point count and
    ``circle``, the smallest circle enclosing its points in plan view (its width)."""

    x_m: float
    y_m: float
    height_m: float
    points: int
    ground_z_m: float
    circle: Circle

    @property
    def width_m(self) -> float:
        """Maximum width: the enclosing circle's diameter."""
        return 2.0 * self.circle.radius_m


@dataclass(frozen=True)
class Circle:
    centre_x_m: float
    centre_y_m: float
    radius_m: float

    def contains(self, point: NDArray[np.float64], tolerance_m: float = 1e-9) -> bool:
        dx, dy = point[0] - self.centre_x_m, point[1] - self.centre_y_m
        return bool(dx * dx + dy * dy <= (self.radius_m + tolerance_m) ** 2)


def _circle_two(a: NDArray[np.float64], b: NDArray[np.float64]) -> Circle:
    centre = (a + b) / 2.0
    return Circle(float(centre[0]), float(centre[1]), float(np.linalg.norm(a - b)) / 2.0)


def circumcentres(
    a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64], min_det: float
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The centres (K, 2) of the circles through the points ``a``, ``b``, ``c`` (each (K, 2)),
    and (K,) which are defined (the triple not collinear: twice its signed area above
    ``min_det``); the others' centres are meaningless."""
    d = 2.0 * (
        a[:, 0] * (b[:, 1] - c[:, 1])
        + b[:, 0] * (c[:, 1] - a[:, 1])
        + c[:, 0] * (a[:, 1] - b[:, 1])
    )
    valid = np.abs(d) >= min_det
    d = np.where(valid, d, 1.0)
    sa, sb, sc = (a * a).sum(1), (b * b).sum(1), (c * c).sum(1)
    ux = (sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1])) / d
    uy = (sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])) / d
    return np.stack([ux, uy], axis=1), valid


def _circle_three(a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64]) -> Circle:
    centres, valid = circumcentres(a[None], b[None], c[None], 1e-15)
    if not valid[0]:  # collinear: the widest pair's circle
        pairs = [(a, b), (a, c), (b, c)]
        return max((_circle_two(p, q) for p, q in pairs), key=lambda circle: circle.radius_m)
    ux, uy = centres[0]
    return Circle(float(ux), float(uy), float(np.hypot(a[0] - ux, a[1] - uy)))


def smallest_enclosing_circle(points_xy: NDArray[np.float64], seed: int = 0) -> Circle:
    """The smallest circle enclosing ``points_xy`` (N, 2): Welzl's algorithm in its iterative
    move-to-front form, expected linear time on shuffled input."""
    if len(points_xy) == 0:
        raise ValueError("no points to enclose")
    points = _hull(np.asarray(points_xy, dtype=np.float64))
    points = points[np.random.default_rng(seed).permutation(len(points))]
    circle = Circle(float(points[0, 0]), float(points[0, 1]), 0.0)
    for i in range(1, len(points)):
        if circle.contains(points[i]):
            continue
        circle = Circle(float(points[i, 0]), float(points[i, 1]), 0.0)
        for j in range(i):
            if circle.contains(points[j]):
                continue
            circle = _circle_two(points[i], points[j])
            for k in range(j):
                if not circle.contains(points[k]):
                    circle = _circle_three(points[i], points[j], points[k])
    return circle


def _hull(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """The convex hull's vertices (the circle depends on nothing else), or all points when
    they are too few or degenerate for a hull."""
    if len(points) < 4:
        return points
    try:
        return points[ConvexHull(points).vertices]  # type: ignore[no-any-return]
    except QhullError:
        return points


def stem_xy_m(points_m: NDArray[np.float64], cell_m: float = STEM_CELL_M) -> NDArray[np.float64]:
    """(2,) where the stem stands: in the lower half of the plant, the xy column (3 x 3 cells
    of ``cell_m``) with points at the most distinct heights. Drooping leaf tips reach low but
    lie flat; the stem is the one tall stack of points."""
    z = points_m[:, 2]
    low = points_m[z <= z.min() + 0.5 * (z.max() - z.min())]
    origin = low.min(axis=0)
    cells = np.floor((low - origin) / cell_m).astype(np.intp)
    occupied = np.zeros(tuple(cells.max(axis=0) + 1), dtype=bool)
    occupied[cells[:, 0], cells[:, 1], cells[:, 2]] = True
    heights = uniform_filter(occupied.sum(axis=2).astype(np.float64), size=3, mode="constant")
    best = np.unravel_index(int(np.argmax(heights)), heights.shape)
    centre = origin[:2] + (np.array(best, dtype=np.float64) + 0.5) * cell_m
    return centre  # type: ignore[no-any-return]


def base_xy_m(points_m: NDArray[np.float64], slice_m: float) -> NDArray[np.float64]:
    """(2,) the foot of the stem: the mean xy of the lowest ``slice_m`` of the points within
    :data:`FOOT_RADIUS_M` of the stem column (:func:`stem_xy_m`)."""
    stem = stem_xy_m(points_m)
    near = np.sum((points_m[:, :2] - stem) ** 2, axis=1) <= FOOT_RADIUS_M**2
    column = points_m[near]
    foot = column[column[:, 2] <= column[:, 2].min() + slice_m]
    return foot[:, :2].mean(axis=0)  # type: ignore[no-any-return]


def local_ground_z_m(
    soil_m: NDArray[np.float64], base_xy: NDArray[np.float64], radius_m: float
) -> float:
    """Median z of the soil points (M, 3) within ``radius_m`` of ``base_xy`` in xy; 0 (the
    fitted ground) when there are none."""
    if len(soil_m) == 0:
        return 0.0
    near = np.sum((soil_m[:, :2] - base_xy) ** 2, axis=1) <= radius_m**2
    return float(np.median(soil_m[near, 2])) if near.any() else 0.0


def robust_top_z_m(points_m: NDArray[np.float64], support_points: int, radius_m: float) -> float:
    """The z of the highest point from which a chain of points, each step within the ellipsoid
    of :data:`TOP_LINK_M` up and :data:`TOP_LINK_ACROSS_M` across, leads :data:`TOP_REACH_M`
    below it: connectivity, not density. A pointed leaf tip sampled one point wide continues
    its leaf point by point and is the top, and so is a thin upright tip whose points scatter
    across; a stray point, or a cluster of flying pixels under ``TOP_REACH_M`` tall, more than
    ``TOP_LINK_M`` above the plant, is not. Only the :data:`TOP_CANDIDATES` highest points are
    tested; when none leads down (a plant under ``TOP_REACH_M`` tall), the highest point with
    at least ``support_points`` other points within ``radius_m``; the highest point of all when
    none has such support."""
    link_m, reach_m = TOP_LINK_M, TOP_REACH_M
    order = np.argsort(points_m[:, 2])[::-1][:TOP_CANDIDATES]
    low = points_m[order[-1], 2] - reach_m - max(link_m, radius_m)
    near_index = np.flatnonzero(points_m[:, 2] >= low)
    near = points_m[near_index]
    # the ellipsoid of a step (TOP_LINK_ACROSS_M across, link_m up) as a ball: heights stretched
    stretched = near * np.array([1.0, 1.0, TOP_LINK_ACROSS_M / link_m])
    pairs = cKDTree(stretched).query_pairs(TOP_LINK_ACROSS_M, output_type="ndarray")
    graph = coo_matrix(
        (np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(len(near),) * 2
    )
    components, labels = connected_components(graph, directed=False)
    lowest = np.full(components, np.inf)
    np.minimum.at(lowest, labels, near[:, 2])
    local = np.empty(len(points_m), dtype=np.intp)
    local[near_index] = np.arange(len(near))
    # a chain from a candidate first goes below ``reach_m`` under it inside this slab: it leads
    # down as far when the lowest point of its component is
    leads = lowest[labels[local[order]]] <= points_m[order, 2] - reach_m
    if leads.any():
        return float(points_m[order[int(np.argmax(leads))], 2])
    counts = cKDTree(near).query_ball_point(points_m[order], radius_m, return_length=True)
    supported = np.flatnonzero(counts - 1 >= support_points)
    chosen = order[supported[0]] if len(supported) else order[0]
    return float(points_m[chosen, 2])


def measure_plant(
    points_m: NDArray[np.float64],
    soil_m: NDArray[np.float64],
    base_slice_m: float,
    ground_radius_m: float,
    top_support_points: int,
    top_support_radius_m: float,
    width_points_m: NDArray[np.float64] | None = None,
) -> PlantTraits:
    """Traits of one plant from its points (N, 3) and the soil around it (M, 3), field frame;
    its width from ``width_points_m`` (K, 3) where given (its points less the mixed pixels,
    :func:`~fieldapp.recon.cloud.width_points`), else from all of them."""
    base = base_xy_m(points_m, base_slice_m)
    ground_z = local_ground_z_m(soil_m, base, ground_radius_m)
    top_z = robust_top_z_m(points_m, top_support_points, top_support_radius_m)
    spread = points_m if width_points_m is None else width_points_m
    circle = smallest_enclosing_circle(spread[:, :2])
    return PlantTraits(
        x_m=float(base[0]),
        y_m=float(base[1]),
        height_m=top_z - ground_z,
        points=len(points_m),
        ground_z_m=ground_z,
        circle=circle,
    )
