"""A simulated world: soil, plants, foam spheres and boards as meshes, with their ground truth.

Field frame: z up, z = 0 on the mean ground, origin at the plot centre, metres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import open3d as o3d
from numpy.typing import NDArray

from devices.sim.boards import PlacedBoard
from devices.sim.canopy import CanopyContacts, PlantSurface, canopy_contacts
from devices.sim.organ_truth import organ_truth
from devices.sim.plants import PlantMesh, make_plant, settle_on_ground, with_dry_tips
from devices.sim.soil import Soil, SoilSpec

SPHERE_DIAMETERS_MM = (200, 300, 350, 400, 500, 600)
"""The reference foam spheres of the accuracy checks."""

FOAM_RGB = np.array([0.93, 0.93, 0.90], dtype=np.float32)
FOAM_IR = 0.80

BodyKind = Literal["soil", "plant", "sphere", "board", "board_back", "wall"]
Texture = Callable[[NDArray[np.floating]], tuple[NDArray[np.float32], NDArray[np.float32]]]
"""Procedural albedo: points (N, 3) -> colour (N, 3) float32 0-1, NIR albedo (N,) float32."""


@dataclass
class Body:
    """One mesh of the world: (V, 3) vertices, (T, 3) triangles, per-vertex albedo (colour
    (V, 3) 0-1 and NIR (V,)), or a ``texture`` that overrides it where a ray hits."""

    name: str
    kind: BodyKind
    vertices_m: NDArray[np.float64]
    triangles: NDArray[np.int32]
    albedo_rgb: NDArray[np.float32]
    albedo_ir: NDArray[np.float32]
    texture: Texture | None = None


@dataclass(frozen=True)
class PlantTruth:
    """A plant's base (``x_m``, ``y_m``, ground height ``z_m`` there), traits and leaf count;
    ``organs``: the stem's diameter and every leaf (:func:`devices.sim.organ_truth.organ_truth`)."""

    name: str
    x_m: float
    y_m: float
    z_m: float
    height_cm: float
    width_cm: float
    leaves: int = 0
    organs: dict[str, Any] | None = None


@dataclass(frozen=True)
class SphereTruth:
    name: str
    x_m: float
    y_m: float
    z_m: float
    diameter_mm: float


@dataclass
class Scene:
    """Bodies to render plus what is true about them."""

    soil: Soil | None
    bodies: list[Body] = field(default_factory=list)
    plants: list[PlantTruth] = field(default_factory=list)
    spheres: list[SphereTruth] = field(default_factory=list)
    boards: list[PlacedBoard] = field(default_factory=list)

    def add_plant(self, name: str, mesh: PlantMesh) -> None:
        self.bodies.append(
            Body(name, "plant", mesh.vertices_m, mesh.triangles, mesh.albedo_rgb, mesh.albedo_ir)
        )
        x, y, z = (float(v) for v in mesh.base_m)
        organs = organ_truth(mesh) if mesh.organ_of_vertex is not None else None
        self.plants.append(
            PlantTruth(name, x, y, z, 100 * mesh.height_m, 100 * mesh.width_m, mesh.leaves, organs)
        )

    def contacts(self) -> CanopyContacts:
        """Which plants touch and whose space each reaches into (from the meshes; about 1 s
        for 16 plants, so computed for the truth file only)."""
        meshes = {b.name: b for b in self.bodies if b.kind == "plant"}
        surfaces = [
            PlantSurface(
                p.name,
                meshes[p.name].vertices_m,
                meshes[p.name].triangles,
                np.array([p.x_m, p.y_m, p.z_m]),
            )
            for p in self.plants
        ]
        return canopy_contacts(surfaces)

    def add_sphere(self, name: str, x_m: float, y_m: float, diameter_mm: float) -> None:
        """A foam sphere resting on the soil at (``x_m``, ``y_m``)."""
        radius = diameter_mm / 2000.0
        z = (self.soil.height_at(x_m, y_m) if self.soil else 0.0) + radius
        sphere = o3d.geometry.TriangleMesh.create_sphere(radius=radius, resolution=48)
        vertices = np.asarray(sphere.vertices) + np.array([x_m, y_m, z])
        triangles = np.asarray(sphere.triangles, dtype=np.int32)
        n = len(vertices)
        self.bodies.append(
            Body(
                name,
                "sphere",
                vertices,
                triangles,
                np.tile(FOAM_RGB, (n, 1)),
                np.full(n, FOAM_IR, np.float32),
            )
        )
        self.spheres.append(SphereTruth(name, x_m, y_m, z, diameter_mm))

    def add_board(self, placed: PlacedBoard) -> None:
        vertices, triangles = placed.board.mesh(placed.T_field_board)
        n = len(vertices)
        grey = np.full((n, 3), 0.5, np.float32)
        front, back = triangles[:2], triangles[2:]
        name = placed.board.name
        self.bodies.append(
            Body(name, "board", vertices, front, grey, np.full(n, 0.5, np.float32), placed.albedo)
        )
        self.bodies.append(
            Body(f"{name}-back", "board_back", vertices, back, grey, np.full(n, 0.4, np.float32))
        )
        self.boards.append(placed)


def empty_scene(seed: int, soil_spec: SoilSpec | None = None) -> Scene:
    """A scene holding only the soil of ``seed``."""
    soil = Soil(soil_spec or SoilSpec(), seed)
    vertices, triangles = soil.mesh()
    n = len(vertices)
    body = Body(
        "soil",
        "soil",
        vertices,
        triangles,
        np.zeros((n, 3), np.float32),
        np.zeros(n, np.float32),
        soil.albedo,
    )
    return Scene(soil=soil, bodies=[body])


@dataclass(frozen=True)
class PlotLayout:
    """Plants in ``rows`` x ``cols`` at ``spacing_m``, centred on the field origin, each moved
    by up to ``jitter_m`` (uniform) from its grid point."""

    rows: int = 4
    cols: int = 4
    spacing_m: float = 0.8
    jitter_m: float = 0.04

    @classmethod
    def for_stations(cls, grid: int, station_spacing_m: float) -> PlotLayout:
        """Plants spread over a plot of ``grid`` x ``grid`` stations: two plant rows and
        columns per station spacing, as on the standard 3 x 3 plot (4 x 4 plants at 0.8 m)."""
        count = max(2 * (grid - 1), 1)
        return cls(rows=count, cols=count, spacing_m=station_spacing_m / 2)

    @property
    def half_extent_m(self) -> float:
        """Half the side of the square the plants' feet stand in (the origin at its centre)."""
        return (max(self.rows, self.cols) - 1) * self.spacing_m / 2 + self.jitter_m

    def positions(self, rng: np.random.Generator) -> NDArray[np.float64]:
        """(rows * cols, 2) plant positions, row by row."""
        ys = (np.arange(self.rows) - (self.rows - 1) / 2) * self.spacing_m
        xs = (np.arange(self.cols) - (self.cols - 1) / 2) * self.spacing_m
        X, Y = np.meshgrid(xs, ys)
        grid = np.stack([X.ravel(), Y.ravel()], axis=1)
        return grid + rng.uniform(-self.jitter_m, self.jitter_m, grid.shape)


def add_plot(
    scene: Scene,
    seed: int,
    day: int,
    layout: PlotLayout,
    stage: str = "seedling",
    plant_model: str = "distichous",
    max_lean_deg: float | None = None,
    leaf_width: float = 1.0,
    grounded_leaves: float = 0.0,
    late_plants: float = 0.0,
    dry_tips_m: float = 0.0,
) -> None:
    """Sow the plot of ``seed`` (positions and plants do not depend on ``day``) at ``stage``
    (:data:`devices.sim.plants.STAGES`) with plants of ``plant_model``
    (:data:`devices.sim.plants.PLANT_MODELS`), leaning up to ``max_lean_deg`` (``None``: as the
    model's plants do), their leaf blades ``leaf_width`` times the model's width, each lower
    leaf coming down to the soil with the chance ``grounded_leaves``. Each plant emerged late
    with the chance ``late_plants`` (:func:`late_draws`) and is a seedling among the others.
    Every leaf's last ``dry_tips_m`` is tan, the soil's colour
    (:func:`devices.sim.plants.with_dry_tips`)."""
    if scene.soil is None:
        raise ValueError("a plot needs soil")
    rng = np.random.default_rng([seed, 11])
    positions = layout.positions(rng)
    late = late_draws(seed, len(positions), late_plants)
    for index, (x, y) in enumerate(positions):
        ground_z = scene.soil.height_at(x, y)
        mesh = make_plant(
            seed * 1000 + index,
            day,
            (x, y),
            ground_z,
            "seedling" if late[index] else stage,
            plant_model,
            max_lean_deg,
            leaf_width,
            grounded_leaves,
        )
        ground = scene.soil.height_m(mesh.vertices_m[:, 0], mesh.vertices_m[:, 1])
        mesh = with_dry_tips(settle_on_ground(mesh, ground), dry_tips_m)
        scene.add_plant(f"p{index + 1:02d}", mesh)


def late_draws(seed: int, count: int, chance: float) -> NDArray[np.bool_]:
    """(count,) which of a plot's plants emerged late, each with ``chance`` (0..1): a plant
    sown with the others that came up days after them (a cold spell, a dry seedbed, a seed
    too deep) is a seedling still when its neighbours' canopies touch. Own draws: 0 gives the
    plot as before, a larger chance makes more of the same plants late."""
    if not 0.0 <= chance <= 1.0:
        raise ValueError(f"late plants: a chance in 0..1, got {chance}")
    draws = np.random.default_rng([seed, 29]).random(count)
    late: NDArray[np.bool_] = draws < chance
    return late


SPHERE_SPOTS_M = ((-0.8, -0.8), (0.8, -0.8), (-0.8, 0.8), (0.8, 0.8), (0.0, -0.8), (0.0, 0.8))
"""Where the spheres rest: between the plants of the standard plot, away from the stations.
Diameters are assigned largest first to the roomiest spots."""


def add_spheres(scene: Scene) -> None:
    """The six reference spheres (600 mm at the first spot, then decreasing)."""
    for spot, diameter in zip(
        SPHERE_SPOTS_M, sorted(SPHERE_DIAMETERS_MM, reverse=True), strict=True
    ):
        scene.add_sphere(f"sphere-{diameter}", spot[0], spot[1], diameter)


SOIL_MARGIN_M = 3.0
"""Soil beyond the outermost stations: more than the camera sees (2.25 m crop, 0.2 m arm)."""


def soil_for_plot(half_extent_m: float) -> SoilSpec:
    """The default soil, wide enough for stations up to ``half_extent_m`` from the origin."""
    return SoilSpec(half_extent_m=max(SoilSpec().half_extent_m, half_extent_m + SOIL_MARGIN_M))


def plot_scene(
    seed: int,
    day: int = 0,
    layout: PlotLayout | None = None,
    soil: SoilSpec | None = None,
    stage: str = "seedling",
    plant_model: str = "distichous",
    max_lean_deg: float | None = None,
    leaf_width: float = 1.0,
    clods_per_m2: float = 0.0,
    grounded_leaves: float = 0.0,
    late_plants: float = 0.0,
    clod_size_m: float | None = None,
    dry_tips_m: float = 0.0,
) -> Scene:
    """The paper's plot: 16 maize plants at 0.8 m on uneven soil (seedlings by default; or
    ``layout``; plants of ``plant_model``, leaning up to ``max_lean_deg``, leaf blades
    ``leaf_width`` times the model's width; ``clods_per_m2``, ``clod_size_m``: :func:`add_clods`;
    ``grounded_leaves``, ``late_plants``, ``dry_tips_m``: :func:`add_plot`)."""
    scene = empty_scene(seed, soil)
    add_plot(
        scene,
        seed,
        day,
        layout or PlotLayout(),
        stage,
        plant_model,
        max_lean_deg,
        leaf_width,
        grounded_leaves,
        late_plants,
        dry_tips_m,
    )
    if clods_per_m2 > 0.0:
        add_clods(scene, seed, clods_per_m2, clod_size_m)
    return scene


CLOD_RADIUS_M = (0.012, 0.04)
CLOD_PROTRUSION_M = (0.01, 0.045)
CLOD_CLEAR_OF_STEMS_M = 0.07
CLOD_REACH_M = 2.0
"""Clods lie out to this far inside the soil's edge (the soil reaches 3 m past the stations)."""


def add_clods(
    scene: Scene, seed: int, per_m2: float, largest_across_m: float | None = None
) -> None:
    """Clods and stones on the soil, ``per_m2`` of them per square metre (a tilled seedbed:
    10-40): partly buried ellipsoids 2.4-8 cm across (up to ``largest_across_m``: a coarse
    seedbed's) standing 1-4.5 cm out of the soil, darker than it (their shaded and moist
    sides), none within 7 cm of a stem. Bodies of kind ``"soil"`` (shadows fall on them; no
    trait is theirs), one mesh for all. The default draws the same clods as before the size
    could be chosen."""
    if scene.soil is None:
        raise ValueError("clods need soil")
    rng = np.random.default_rng([seed, 23])
    radii = (CLOD_RADIUS_M[0], largest_across_m / 2.0 if largest_across_m else CLOD_RADIUS_M[1])
    half = scene.soil.spec.half_extent_m - CLOD_REACH_M
    count = round(per_m2 * (2 * half) ** 2)
    xy = rng.uniform(-half, half, (count, 2))
    stems = np.array([[p.x_m, p.y_m] for p in scene.plants]).reshape(-1, 2)
    if len(stems):
        nearest = np.min(np.linalg.norm(xy[:, None, :] - stems[None, :, :], axis=2), axis=1)
        xy = xy[nearest > CLOD_CLEAR_OF_STEMS_M + radii[1]]
    unit = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=5)
    unit_vertices = np.asarray(unit.vertices)
    unit_triangles = np.asarray(unit.triangles, dtype=np.int32)
    grounds = scene.soil.height_m(xy[:, 0], xy[:, 1])
    vertices, triangles, shade = [], [], []
    for i, ((x, y), ground) in enumerate(zip(xy, grounds, strict=True)):
        rx, ry = rng.uniform(*radii, 2)
        out = min(rng.uniform(*CLOD_PROTRUSION_M), 1.2 * max(rx, ry))
        rz = out * rng.uniform(0.9, 1.6)
        turn = rng.uniform(0.0, 2 * np.pi)
        c, s_ = np.cos(turn), np.sin(turn)
        local = unit_vertices * np.array([rx, ry, rz])
        local[:, :2] = local[:, :2] @ np.array([[c, s_], [-s_, c]])
        vertices.append(local + np.array([x, y, ground + out - rz]))
        triangles.append(unit_triangles + i * len(unit_vertices))
        shade.append(np.full(len(unit_vertices), rng.uniform(0.5, 0.9)))
    if not vertices:
        return
    points = np.concatenate(vertices)
    rgb, ir = scene.soil.albedo(points)
    factor = np.concatenate(shade).astype(np.float32)
    factor *= rng.uniform(0.95, 1.05, len(points)).astype(np.float32)
    scene.bodies.append(
        Body(
            "clods",
            "soil",
            points,
            np.concatenate(triangles),
            (rgb * factor[:, None]).astype(np.float32),
            (ir * factor).astype(np.float32),
        )
    )


def spheres_scene(
    seed: int,
    day: int = 0,
    with_plants: bool = False,
    layout: PlotLayout | None = None,
    soil: SoilSpec | None = None,
) -> Scene:
    """The six reference spheres on the soil, optionally among the plot's plants."""
    scene = empty_scene(seed, soil)
    if with_plants:
        add_plot(scene, seed, day, layout or PlotLayout())
    add_spheres(scene)
    return scene


def bare_soil_scene(seed: int, soil: SoilSpec | None = None) -> Scene:
    """Nothing but the uneven soil: its relief is the only feature the registration has."""
    return empty_scene(seed, soil)
