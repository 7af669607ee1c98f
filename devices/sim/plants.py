"""Procedural maize plants: a leaning stem and 5-9 arching, tapering leaves on alternate sides.

A plant is drawn from its own seed, independently of its growth stage: ``--day N`` grows the
same plants (leaves appear every five days, everything lengthens), and the same seed gives the
same plants. Two stages (:data:`STAGES`): ``seedling`` (the paper's plots, 26-35 cm on day 0)
and ``touching`` (the later scan dates: 55-90 cm, 5-8 leaves, long leaves that reach across the
80 cm spacing into the neighbours' space). Truth (height, width) is computed from the finished
mesh.

This is the ``distichous`` model, the default; :data:`PLANT_MODELS` names the second,
``irregular`` (:mod:`devices.sim.plants_irregular`), drawn through the same :func:`make_plant`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from devices.geometry import rotation_x, rotation_z

MAX_LEAVES = 9
LEAF_SEGMENTS = 14
STEM_SIDES = 8
HEIGHT_DAY0_M = 0.30
GROWTH_PER_DAY = 0.05
"""Relative height gain per day (linear): 1.25 x on day 5, 2 x on day 20."""

STAGES = ("seedling", "touching")
PLANT_MODELS = ("distichous", "irregular")
"""``distichous`` (the default, this module's) and ``irregular``
(:mod:`devices.sim.plants_irregular`, held out from the plants step's tuning)."""
LEAN_DEG = (1.0, 5.0)
"""This model's stems lean this many degrees (uniform), each in its own direction."""
MAX_LEAN_DEG = 30.0
"""The largest lean a plot can be asked for (``max_lean_deg``): lodging is not simulated."""
LEAF_WIDTH_RANGE = (0.3, 1.5)
"""How much narrower or broader than the model's own a plot's leaf blades can be asked for
(``leaf_width``). The first model's seedling blades are 5-11 cm wide, the second's about 4.5:
a maize seedling's are 1.5-4 cm at V2-V5, so 0.3-0.5 is the real plant's."""
TOUCHING_HEIGHT_M = (0.55, 0.90)
"""Heights of the ``touching`` stage (uniform; ``--day`` does not change them)."""
TOUCHING_LEAF_REACH = 1.8
"""Leaf length relative to the seedling model's at the ``touching`` stage: the canopy spreads
to 1.0-1.5 m across, so leaves cross the 80 cm spacing."""

GROUNDED_TIP_DEG = 176.0
"""A grounded leaf's midrib ends this far from the vertical: it comes down to the soil nearly
straight, as an old lower leaf arching over does."""
GROUNDED_BEND_AT = 0.6
"""A grounded leaf has turned fully down at this share of its length."""
GROUNDED_REACH_M = 0.05
"""A grounded leaf is long enough to reach this far below the ground (model units, before the
plant is scaled; :func:`settle_on_ground` lays what would be under the soil on it)."""

LEAF_RGB = np.array([0.14, 0.36, 0.06], dtype=np.float32)
STEM_RGB = np.array([0.45, 0.55, 0.25], dtype=np.float32)
LEAF_IR = 0.55
"""Near-infrared albedo of green leaves (high: the red edge)."""
STEM_PART = -1
"""``PlantMesh.organ_of_vertex`` of the stem's vertices."""


@dataclass(frozen=True)
class PlantMesh:
    """One plant in the field frame.

    - ``vertices_m``: (V, 3) float64; ``triangles``: (T, 3) int32.
    - ``albedo_rgb``: (V, 3) float32 0-1; ``albedo_ir``: (V,) float32.
    - ``base_m``: (3,) the stem's foot on the ground.
    - ``organ_of_vertex``: (V,) int16, :data:`STEM_PART` for the stem, k for leaf k (0 lowest);
      ``None`` when unknown. The organ truth (:mod:`devices.sim.organ_truth`) is read from it.
    - ``leaves``: how many leaves it has.
    - ``stem_sides``: vertices per ring of the stem (its first vertices, rings bottom up);
      ``section_vertices``: vertices per cross-section of a leaf (margin to margin, the midrib
      the middle one). The organ truth reads the mesh through them.
    """

    vertices_m: NDArray[np.float64]
    triangles: NDArray[np.int32]
    albedo_rgb: NDArray[np.float32]
    albedo_ir: NDArray[np.float32]
    base_m: NDArray[np.float64]
    organ_of_vertex: NDArray[np.int16] | None = None
    leaves: int = 0
    stem_sides: int = STEM_SIDES
    section_vertices: int = 3

    @property
    def height_m(self) -> float:
        """From the ground at the base to the highest point of the mesh."""
        return float(self.vertices_m[:, 2].max() - self.base_m[2])

    @property
    def width_m(self) -> float:
        """Diameter of the smallest circle enclosing the projection on the ground."""
        _, radius = cv2.minEnclosingCircle(self.vertices_m[:, :2].astype(np.float32))
        return 2.0 * float(radius)


def leaves_on_day(base_leaves: int, day: int) -> int:
    """Visible leaves on ``day``: one more every five days, at most :data:`MAX_LEAVES`."""
    return int(min(MAX_LEAVES, base_leaves + max(day, 0) // 5))


def check_leaf_width(leaf_width: float) -> float:
    """``leaf_width`` if it is within :data:`LEAF_WIDTH_RANGE`."""
    low, high = LEAF_WIDTH_RANGE
    if not low <= leaf_width <= high:
        raise ValueError(f"leaf_width must be within {low:g}..{high:g}, got {leaf_width!r}")
    return leaf_width


def check_lean(max_lean_deg: float) -> float:
    """``max_lean_deg`` if it is a lean a plot can have (0 to :data:`MAX_LEAN_DEG`)."""
    if not 0.0 <= max_lean_deg <= MAX_LEAN_DEG:
        raise ValueError(f"max_lean_deg must be within 0..{MAX_LEAN_DEG:g}, got {max_lean_deg!r}")
    return max_lean_deg


def growth_factor(day: int) -> float:
    """Height relative to day 0."""
    return 1.0 + GROWTH_PER_DAY * max(day, 0)


def make_plant(
    seed: int,
    day: int,
    base_xy_m: tuple[float, float],
    ground_z_m: float,
    stage: str = "seedling",
    model: str = "distichous",
    max_lean_deg: float | None = None,
    leaf_width: float = 1.0,
    grounded_leaves: float = 0.0,
) -> PlantMesh:
    """Draw the plant of ``seed`` on ``day`` at ``stage`` (one of :data:`STAGES`), standing at
    ``base_xy_m`` on ground ``ground_z_m``, from plant ``model`` (one of :data:`PLANT_MODELS`).
    ``max_lean_deg``: the model's lean range scaled to end there (same draws, so the same plant
    leaning more or less); ``None``: the model's own. ``leaf_width``: every leaf blade that many
    times as wide as the model draws it (:data:`LEAF_WIDTH_RANGE`; same draws otherwise).
    ``grounded_leaves``: the chance (0..1) that each leaf of the plant's lower half arches over
    and comes down to the soil (:func:`grounded_theta`, :func:`grounded_length`; own draws, so
    0 gives the plant as before and a larger share grounds more of the same leaves).

    Leaf tips may droop below uneven soil: lift them with :func:`settle_on_ground`.
    """
    if stage not in STAGES:
        raise ValueError(f"stage must be one of {', '.join(STAGES)}, got {stage!r}")
    if model not in PLANT_MODELS:
        raise ValueError(f"plant model must be one of {', '.join(PLANT_MODELS)}, got {model!r}")
    check_leaf_width(leaf_width)
    grounded = grounded_draws(seed, grounded_leaves)
    if model == "irregular":
        from devices.sim.plants_irregular import make_irregular_plant

        return make_irregular_plant(
            seed, day, base_xy_m, ground_z_m, stage, max_lean_deg, leaf_width, grounded
        )
    rng = np.random.default_rng([seed, 7])
    base_leaves = int(rng.integers(5, 8))
    count = leaves_on_day(base_leaves, day)
    azimuth0, lean_dir = rng.uniform(0.0, 2 * np.pi, 2)
    lean_deg = rng.uniform(*LEAN_DEG)
    if max_lean_deg is not None:
        lean_deg *= check_lean(max_lean_deg) / LEAN_DEG[1]
    size = rng.uniform(0.85, 1.15)
    height_m = HEIGHT_DAY0_M * size * growth_factor(day)
    reach = 1.0
    if stage == "touching":  # own draws: the seedling stage's plants stay as they were
        grown = np.random.default_rng([seed, 7, 1])
        count = int(grown.integers(5, 9))
        height_m = float(grown.uniform(*TOUCHING_HEIGHT_M))
        reach = TOUCHING_LEAF_REACH
        azimuth0 = float(np.radians(grown.uniform(-30.0, 30.0)))  # leaves along the rows
    parts = [_stem(count)]
    for k in range(MAX_LEAVES):
        params = rng.uniform(0.0, 1.0, 6)  # drawn for every leaf, so growth keeps the old ones
        if k < count:
            down = bool(grounded[k]) and k <= (count - 1) / 2
            parts.append(_leaf(k, count, azimuth0 + np.pi * k, params, reach, leaf_width, down))
    vertices = np.concatenate([p[0] for p in parts])
    triangles = np.concatenate(_offset_triangles([p[1] for p in parts])).astype(np.int32)
    albedo = np.concatenate([p[2] for p in parts])
    organ = np.concatenate(
        [np.full(len(p[0]), k - 1 if k else STEM_PART, np.int16) for k, p in enumerate(parts)]
    )
    leaning = (
        rotation_z(np.degrees(lean_dir)) @ rotation_x(lean_deg) @ rotation_z(-np.degrees(lean_dir))
    )
    vertices = vertices @ leaning.T
    vertices *= height_m / vertices[:, 2].max()
    base = np.array([base_xy_m[0], base_xy_m[1], ground_z_m])
    vertices += base
    shade = 1.0 + 0.12 * (rng.random() - 0.5)
    return PlantMesh(
        vertices_m=vertices,
        triangles=triangles,
        albedo_rgb=(albedo * shade).astype(np.float32),
        albedo_ir=np.full(len(vertices), LEAF_IR, np.float32),
        base_m=base,
        organ_of_vertex=organ,
        leaves=count,
    )


def grounded_draws(seed: int, share: float) -> NDArray[np.bool_]:
    """(MAX_LEAVES,) which leaves of the plant of ``seed`` would come down to the soil at
    ``share`` (each of the lower half's with that chance; the models keep the lower half)."""
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"grounded leaves must be a share from 0 to 1, got {share}")
    return np.random.default_rng([seed, 7, 2]).uniform(0.0, 1.0, MAX_LEAVES) < share


def grounded_theta(u: NDArray[np.float64], rise: float) -> NDArray[np.float64]:
    """A grounded leaf's midrib: its angle from the vertical at each of the sections ``u`` (0..1
    along it, equally spaced), rising at ``rise`` (radians) and turned down to
    :data:`GROUNDED_TIP_DEG` by :data:`GROUNDED_BEND_AT` of its length."""
    tip = np.radians(GROUNDED_TIP_DEG)
    turned: NDArray[np.float64] = rise + (tip - rise) * np.minimum(u / GROUNDED_BEND_AT, 1.0) ** 1.2
    return turned


def grounded_length(
    u: NDArray[np.float64], theta: NDArray[np.float64], node_z: float, length: float
) -> float:
    """A grounded leaf's length: at least ``length``, and enough for the midrib of angles
    ``theta`` at the sections ``u`` to come from ``node_z`` down to :data:`GROUNDED_REACH_M`
    under the ground."""
    lowest = float(np.min(np.cumsum(np.diff(u, prepend=0.0) * np.cos(theta))))
    return max(length, (node_z + GROUNDED_REACH_M) / -lowest)


def settle_on_ground(mesh: PlantMesh, ground_z_m: NDArray[np.float64]) -> PlantMesh:
    """Lift vertices that droop below the ground (``ground_z_m`` (V,) under each) 5 mm clear of
    it, except the stem's foot, which stays rooted."""
    vertices = mesh.vertices_m.copy()
    above_foot = vertices[:, 2] > mesh.base_m[2] + 0.01
    floor = ground_z_m + 0.005
    lift = above_foot & (vertices[:, 2] < floor)
    vertices[lift, 2] = floor[lift]
    return replace(mesh, vertices_m=vertices)


def _offset_triangles(parts: list[NDArray[np.int64]]) -> list[NDArray[np.int64]]:
    out, offset = [], 0
    for triangles in parts:
        out.append(triangles + offset)
        offset += int(triangles.max()) + 1
    return out


Part = tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float32]]


def _stem(count: int) -> Part:
    """A tapering cylinder (unit scale: the plant is scaled afterwards), foot 2 cm in the soil."""
    top = 0.10 + 0.035 * count
    z = np.linspace(-0.02, top, 6)
    radius = np.interp(z, [-0.02, top], [0.012, 0.006])
    angle = np.linspace(0.0, 2 * np.pi, STEM_SIDES, endpoint=False)
    ring = np.stack([np.cos(angle), np.sin(angle)], 1)
    vertices = np.concatenate(
        [
            np.column_stack([r * ring, np.full(STEM_SIDES, h)])
            for r, h in zip(radius, z, strict=True)
        ]
    )
    triangles = _strip(len(z), STEM_SIDES, closed=True)
    albedo = np.tile(STEM_RGB, (len(vertices), 1))
    return vertices, triangles, albedo


def _leaf(
    k: int,
    count: int,
    azimuth: float,
    p: NDArray[np.float64],
    reach: float = 1.0,
    breadth: float = 1.0,
    grounded: bool = False,
) -> Part:
    """Leaf ``k`` of ``count`` (0 lowest) as a folded ribbon with three vertices per section,
    ``reach`` times the seedling's length, ``breadth`` times its width; ``grounded``: arching
    over down to the soil (:func:`grounded_theta`).

    Lower leaves are shorter, start flatter and arch over; the top ones stand up in the whorl.
    """
    rank = k / max(count - 1, 1)
    node_z = 0.06 + 0.035 * k
    length = reach * (0.20 + 0.22 * np.sin(np.pi * (0.25 + 0.6 * rank))) * (0.85 + 0.3 * p[0])
    width = (0.05 + 0.06 * np.sin(np.pi * min(rank, 0.92))) * (0.85 + 0.3 * p[1]) * breadth
    rise = np.radians(np.interp(rank, [0, 0.7, 1], [45, 30, 8]) + 10 * (p[2] - 0.5))
    tip = np.radians(np.interp(rank, [0, 0.7, 1], [135, 105, 35]) + 20 * (p[3] - 0.5))
    az = (
        azimuth
        + np.radians(30 * (p[4] - 0.5))
        + np.radians(20 * (p[5] - 0.5)) * np.linspace(0, 1, LEAF_SEGMENTS + 1)
    )
    u = np.linspace(0.0, 1.0, LEAF_SEGMENTS + 1)
    if grounded:
        theta = grounded_theta(u, rise)
        length = grounded_length(u, theta, node_z, length)
    else:
        theta = rise + (tip - rise) * u**1.5
    heading = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], 1)
    tangent = np.sin(theta)[:, None] * heading + np.cos(theta)[:, None] * np.array([0, 0, 1.0])
    steps = np.diff(u, prepend=0.0)[:, None] * length * tangent
    centre = np.cumsum(steps, axis=0) + np.array([0.0, 0.0, node_z])
    side = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], 1)
    upper = np.cross(side, tangent)
    half = 0.5 * width * (0.3 + 0.7 * np.sin(0.5 * np.pi * np.minimum(u / 0.4, 1))) * (1 - u) ** 0.6
    fold = (0.3 * half)[:, None] * upper
    sections = [centre - half[:, None] * side + fold, centre, centre + half[:, None] * side + fold]
    vertices = np.stack(sections, axis=1).reshape(-1, 3)
    triangles = _strip(LEAF_SEGMENTS + 1, 3, closed=False)
    midrib = np.tile([0.0, 1.0, 0.0], LEAF_SEGMENTS + 1)
    tint = (1.0 + 0.25 * np.repeat(u, 3) ** 2 + 0.15 * midrib)[:, None]
    albedo = (LEAF_RGB[None, :] * tint).astype(np.float32)
    albedo[:, 0] += 0.04 * np.repeat(u, 3) ** 3  # tips a little yellower
    return vertices, triangles, albedo


DRY_TIP_RGB = np.array([0.48, 0.34, 0.22], dtype=np.float32)
"""A dry leaf tip's tan (excess green about 0 in the image's sRGB, as the soil's: 0.004 against
the loam's 0.0 and the leaves' 0.2-0.5)."""
DRY_TIP_RANGE_M = (0.0, 0.15)


def with_dry_tips(mesh: PlantMesh, dry_m: float) -> PlantMesh:
    """``mesh`` with the last ``dry_m`` (along the midrib) of every leaf tan, the soil's colour
    (:data:`DRY_TIP_RGB`): tips that dried (drought, nitrogen, a late frost), or, seen from 2 m,
    the last pixels of a tip whose colour mixes with the soil's. The shape, and so the truth,
    is unchanged. Leaves are read section by section (``section_vertices``, base to tip)."""
    low, high = DRY_TIP_RANGE_M
    if not low <= dry_m <= high:
        raise ValueError(f"dry tips must be within {low:g}..{high:g} m, got {dry_m!r}")
    if mesh.organ_of_vertex is None or dry_m == 0.0:
        return mesh
    albedo = mesh.albedo_rgb.copy()
    for leaf in range(mesh.leaves):
        at = np.flatnonzero(mesh.organ_of_vertex == leaf)
        sections = mesh.vertices_m[at].reshape(-1, mesh.section_vertices, 3).mean(axis=1)
        steps = np.linalg.norm(np.diff(sections, axis=0), axis=1)
        from_tip = np.concatenate([np.cumsum(steps[::-1])[::-1], [0.0]])
        dry = np.repeat(from_tip < dry_m, mesh.section_vertices)
        albedo[at[dry]] = DRY_TIP_RGB
    return replace(mesh, albedo_rgb=albedo)


def _strip(rings: int, per_ring: int, closed: bool) -> NDArray[np.int64]:
    """Triangles joining ``rings`` consecutive rings of ``per_ring`` vertices each."""
    columns = per_ring if closed else per_ring - 1
    r, c = np.meshgrid(np.arange(rings - 1), np.arange(columns), indexing="ij")
    a = (r * per_ring + c).ravel()
    b = (r * per_ring + (c + 1) % per_ring).ravel()
    return np.concatenate(
        [np.stack([a, b, a + per_ring], 1), np.stack([b, b + per_ring, a + per_ring], 1)]
    )
