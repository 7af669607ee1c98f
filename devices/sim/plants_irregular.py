"""A second procedural maize model, ``irregular``: held out from the tuning of the plants step.

Specified on its own, in metres, from how field maize looks (not by perturbing
:mod:`devices.sim.plants`), and different from the first model where real plants differ from it:

- **Phyllotaxy**: leaf k at the plant's azimuth + 180 deg x k plus a per-leaf deviation (normal,
  sd :data:`PHYLLOTAXY_SD_DEG`); the plant's azimuth is uniform at both stages (never set along
  the rows), and each midrib drifts sideways along its length.
- **Insertion heights**: internodes lengthening up the stem, each with its own noise.
- **Midrib**: its angle from the vertical grows as a power > 1 of the arc length (curvature
  growing towards the tip); three habits drawn per leaf: near-erect (tip 25-60 deg from the
  vertical), arching (100-140 deg) and drooping tip-down (150-175 deg).
- **Blade**: five vertices per section (margin, half, midrib, half, margin), U-shaped across
  (the midrib in a groove), twisted about the midrib along its length (-70..70 deg at the tip),
  wavy margins (a wave of 4-7 cm, amplitude up to a fifth of the half width, left and right out
  of phase); the width rises from 40 % at the collar to its maximum at 55-70 % of the length
  and tapers to a point.
- **Stem**: elliptic (axes 1.15-1.35 : 1), thicker, 12 sides, rings every couple of cm.
- **Mesh**: about one section per 1.5 cm of leaf (16-60).
- **Colour**: each leaf its own green (still clearly green: excess green > 0.2 on the albedo),
  a lighter midrib, yellower tips, older leaves paler; per-leaf near-infrared albedo.

Both stages: ``seedling`` (24-38 cm on day 0, 4-7 leaves, the longest 0.8-1.1 x the height,
growing with ``day`` as the first model does) and ``touching`` (60-95 cm, 6-9 leaves, the longest
0.95-1.15 x the height as built, so 45-110 cm; own draws, the seedlings unchanged by them).
Each plant is built near size, then scaled to its drawn height, as the first model's are (built
to size, some touching plants reached 117 cm, above what the rig's camera sees whole). Truth
(height, width, organs) is read from the finished mesh, as for the first model.
"""

from __future__ import annotations

from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

from devices.geometry import rotation_x, rotation_z
from devices.sim.plants import (
    MAX_LEAVES,
    STEM_PART,
    Part,
    PlantMesh,
    _offset_triangles,
    _strip,
    check_lean,
    grounded_length,
    grounded_theta,
    growth_factor,
    leaves_on_day,
)

STEM_SIDES = 12
SECTION_VERTICES = 5
PHYLLOTAXY_SD_DEG = 20.0
SEGMENT_M = 0.015
SEEDLING_HEIGHT_M = (0.24, 0.38)
TOUCHING_HEIGHT_M = (0.60, 0.95)
SEEDLING_LONGEST_LEAF = (0.8, 1.1)
"""The longest leaf relative to the plant's height (seedlings)."""
TOUCHING_LONGEST_LEAF = (0.95, 1.15)
"""The longest leaf relative to the plant's height (touching stage: 55-100 cm long)."""
HABITS = ("erect", "arching", "drooping")
LEAN_DEG = (0.0, 6.0)
"""This model's stems lean this many degrees (uniform), each in its own direction."""


def make_irregular_plant(
    seed: int,
    day: int,
    base_xy_m: tuple[float, float],
    ground_z_m: float,
    stage: str,
    max_lean_deg: float | None = None,
    leaf_width: float = 1.0,
    grounded: NDArray[np.bool_] | None = None,
) -> PlantMesh:
    """The ``irregular`` plant of ``seed`` on ``day`` at ``stage`` standing at ``base_xy_m``
    (``max_lean_deg``, ``leaf_width``: as :func:`devices.sim.plants.make_plant`'s; ``grounded``:
    which leaves of the lower half come down to the soil, by index)."""
    rng = np.random.default_rng([seed, 29])
    base_leaves = int(rng.integers(4, 8))
    count = leaves_on_day(base_leaves, day)
    height_m = float(rng.uniform(*SEEDLING_HEIGHT_M)) * growth_factor(day)
    longest_m = height_m * float(rng.uniform(*SEEDLING_LONGEST_LEAF))
    stem_diameter_m = height_m * float(rng.uniform(0.04, 0.05))
    breadth = 0.15  # leaf width per length: seedlings' leaves are broad for their length
    if stage == "touching":  # own draws: the seedlings stay as they are
        grown = np.random.default_rng([seed, 29, 1])
        count = int(grown.integers(6, MAX_LEAVES + 1))
        height_m = float(grown.uniform(*TOUCHING_HEIGHT_M))
        longest_m = height_m * float(grown.uniform(*TOUCHING_LONGEST_LEAF))
        stem_diameter_m = float(grown.uniform(0.022, 0.03))
        breadth = 0.10
    breadth *= leaf_width
    azimuth0 = float(rng.uniform(0.0, 2 * np.pi))
    lean_dir = float(rng.uniform(0.0, 360.0))
    lean_deg = float(rng.uniform(*LEAN_DEG))
    if max_lean_deg is not None:
        lean_deg *= check_lean(max_lean_deg) / LEAN_DEG[1]
    ellipse = float(rng.uniform(1.15, 1.35))
    internodes = np.cumsum(np.linspace(1.0, 2.2, MAX_LEAVES) * rng.lognormal(0.0, 0.2, MAX_LEAVES))
    insertion_span = float(rng.uniform(0.40, 0.55)) * height_m
    first_node = float(rng.uniform(0.02, 0.05)) * np.sqrt(height_m / 0.3)
    nodes = first_node + insertion_span * (internodes - internodes[0]) / internodes[count - 1]
    parts = []
    for k in range(MAX_LEAVES):
        draws = rng.uniform(0.0, 1.0, 16)  # every leaf's, so a growing plant keeps its old ones
        if k < count:
            rank = k / max(count - 1, 1)
            azimuth = azimuth0 + np.pi * k + np.radians(PHYLLOTAXY_SD_DEG) * _normal(draws[0])
            down = grounded is not None and bool(grounded[k]) and rank <= 0.5
            parts.append(_leaf(rank, float(nodes[k]), azimuth, longest_m, breadth, draws, down))
    top = float(nodes[count - 1]) + 0.04 * height_m
    parts.insert(0, _stem(top, 0.5 * stem_diameter_m, ellipse, azimuth0))
    vertices = np.concatenate([p[0] for p in parts])
    triangles = np.concatenate(_offset_triangles([p[1] for p in parts])).astype(np.int32)
    albedo = np.concatenate([p[2] for p in parts])
    ir = np.concatenate([np.full(len(p[0]), 0.5 + 0.1 * rng.random()) for p in parts])
    organ = np.concatenate(
        [np.full(len(p[0]), k - 1 if k else STEM_PART, np.int16) for k, p in enumerate(parts)]
    )
    leaning = rotation_z(lean_dir) @ rotation_x(lean_deg) @ rotation_z(-lean_dir)
    vertices = vertices @ leaning.T
    vertices *= height_m / vertices[:, 2].max()  # built near size, held to the stage's heights
    base = np.array([base_xy_m[0], base_xy_m[1], ground_z_m])
    vertices += base
    shade = float(rng.uniform(0.92, 1.08))
    return PlantMesh(
        vertices_m=vertices,
        triangles=triangles,
        albedo_rgb=np.clip(albedo * shade, 0.0, 1.0).astype(np.float32),
        albedo_ir=ir.astype(np.float32),
        base_m=base,
        organ_of_vertex=organ,
        leaves=count,
        stem_sides=STEM_SIDES,
        section_vertices=SECTION_VERTICES,
    )


def _normal(u: float) -> float:
    """A standard normal deviate from a uniform draw (each leaf's draws are all uniform)."""
    return NormalDist().inv_cdf(min(max(u, 1e-6), 1 - 1e-6))


def _stem(top_m: float, radius_m: float, ellipse: float, azimuth: float) -> Part:
    """An elliptic, tapering prism from 2 cm in the soil to ``top_m`` (the whorl), its long axis
    across the leaves' plane."""
    rings = max(int(np.ceil((top_m + 0.02) / 0.02)) + 1, 6)
    z = np.linspace(-0.02, top_m, rings)
    radius = radius_m * np.interp(z, [-0.02, 0.6 * top_m, top_m], [1.0, 0.8, 0.45])
    angle = np.linspace(0.0, 2 * np.pi, STEM_SIDES, endpoint=False)
    a, b = np.sqrt(ellipse), 1.0 / np.sqrt(ellipse)
    ring = np.stack([a * np.cos(angle), b * np.sin(angle)], 1)
    turn = azimuth + np.pi / 2
    ring = ring @ np.array([[np.cos(turn), np.sin(turn)], [-np.sin(turn), np.cos(turn)]])
    vertices = np.concatenate(
        [
            np.column_stack([r * ring, np.full(STEM_SIDES, h)])
            for r, h in zip(radius, z, strict=True)
        ]
    )
    triangles = _strip(rings, STEM_SIDES, closed=True)
    colour = np.array([0.40, 0.52, 0.20]) * np.interp(z, [-0.02, top_m], [0.9, 1.05])[:, None]
    albedo = np.repeat(colour, STEM_SIDES, axis=0).astype(np.float32)
    return vertices, triangles, albedo


def _leaf(
    rank: float,
    node_m: float,
    azimuth: float,
    longest_m: float,
    breadth: float,
    d: NDArray[np.float64],
    grounded: bool = False,
) -> Part:
    """One leaf from the stem's axis at height ``node_m``; ``rank`` 0 lowest, 1 highest;
    ``breadth`` its mean maximum width per length; ``d`` its 16 uniform draws; ``grounded``:
    arching over down to the soil (:func:`devices.sim.plants.grounded_theta`)."""
    length = longest_m * max(0.45, 1.0 - ((rank - 0.6) / 0.85) ** 2) * np.exp(0.1 * _normal(d[1]))
    width = length * breadth * (0.8 + 0.4 * d[2]) * (0.75 if rank > 0.85 else 1.0)
    habit = _habit(rank, d[3])
    theta0 = np.radians({"erect": 12.0, "arching": 28.0, "drooping": 38.0}[habit] + 14 * d[4])
    tip = np.radians(
        {"erect": 25.0 + 35 * d[5], "arching": 100.0 + 40 * d[5], "drooping": 150.0 + 25 * d[5]}[
            habit
        ]
    )
    power = 1.3 + 1.2 * d[6]  # the angle grows as u ** power: curvature growing along the leaf
    if grounded:  # long enough to reach the soil, then as many sections as that needs
        fine = np.linspace(0.0, 1.0, 61)
        length = grounded_length(fine, grounded_theta(fine, theta0), node_m, length)
    segments = int(np.clip(round(length / SEGMENT_M), 16, 60))
    u = np.linspace(0.0, 1.0, segments + 1)
    theta = grounded_theta(u, theta0) if grounded else theta0 + (tip - theta0) * u**power
    drift = np.radians(25.0) * (d[7] - 0.5) * u**1.5  # the midrib sweeping sideways
    az = azimuth + drift
    heading = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], 1)
    tangent = np.sin(theta)[:, None] * heading + np.cos(theta)[:, None] * np.array([0, 0, 1.0])
    mid = 0.5 * (tangent[1:] + tangent[:-1])
    centre = np.vstack(
        [[0.0, 0.0, node_m], [0.0, 0.0, node_m] + np.cumsum(mid, 0) * length / segments]
    )
    side = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], 1)
    side -= np.sum(side * tangent, 1)[:, None] * tangent
    side /= np.linalg.norm(side, axis=1)[:, None]
    twist = np.radians(140.0 * (d[8] - 0.5)) * u**1.2
    normal = np.cross(tangent, side)
    side, normal = (
        np.cos(twist)[:, None] * side + np.sin(twist)[:, None] * normal,
        np.cos(twist)[:, None] * normal - np.sin(twist)[:, None] * side,
    )
    peak = 0.55 + 0.15 * d[9]
    profile = np.where(
        u < peak,
        0.4 + 0.6 * np.sin(0.5 * np.pi * u / peak),
        np.clip((1.0 - u) / (1.0 - peak), 0.0, 1.0) ** 0.8,
    )
    half = 0.5 * width * profile
    groove = (0.15 + 0.15 * d[10]) * half
    wave_m = 0.04 + 0.03 * d[11]
    s = u * length
    ramp = np.clip(u / 0.3, 0.0, 1.0)
    amplitude = (0.08 + 0.12 * d[12]) * half * ramp
    left = amplitude * np.sin(2 * np.pi * s / wave_m + 2 * np.pi * d[13])
    right = amplitude * np.sin(2 * np.pi * s / wave_m + 2 * np.pi * d[13] + np.pi * (0.5 + d[14]))
    across = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
    lift = np.array([left, 0.25 * left, 0 * left, 0.25 * right, right]).T  # (S, 5)
    offsets = (
        across[None, :, None] * half[:, None, None] * side[:, None, :]
        + (groove[:, None] * across[None, :] ** 2 + lift)[:, :, None] * normal[:, None, :]
    )
    vertices = (centre[:, None, :] + offsets).reshape(-1, 3)
    triangles = _strip(segments + 1, SECTION_VERTICES, closed=False)
    green = 0.30 + 0.12 * d[15]
    base_rgb = np.array([green * (0.30 + 0.25 * d[2]), green, green * (0.10 + 0.15 * d[9])])
    base_rgb *= 1.0 + 0.25 * (1.0 - rank) * (d[4] > 0.5)  # some older leaves paler
    along = np.repeat(u, SECTION_VERTICES)
    midrib = np.tile([0.0, 0.0, 1.0, 0.0, 0.0], segments + 1)
    albedo = base_rgb[None, :] * (1.0 + 0.12 * midrib + 0.1 * along)[:, None]
    albedo[:, 0] += 0.06 * along**3  # tips yellower
    return vertices, triangles, albedo.astype(np.float32)


def _habit(rank: float, draw: float) -> str:
    """Upper leaves mostly near-erect, lower ones arching or drooping."""
    erect = float(np.interp(rank, [0.0, 0.6, 1.0], [0.05, 0.15, 0.8]))
    drooping = float(np.interp(rank, [0.0, 0.6, 1.0], [0.35, 0.25, 0.0]))
    if draw < erect:
        return "erect"
    return "drooping" if draw < erect + drooping else "arching"
