"""A plant on a turntable in a room: the lab rig most public turntable recordings come from.

The camera stands still on a tripod; a maize plant in a tray of soil stands on a turntable on
a bench, and the table turns the plant by the view step between captures. The room (floor,
walls, the bench, a cabinet, a box beside the table) does not turn. Frame ("table frame"): z
up along the table's axis, origin on the axis at the soil surface of the tray, metres; at
table angle 0 the plant's truth is given in this frame.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import KINECT_V2_PAPER, Frame, Intrinsics
from devices.geometry import Matrix4, make_transform, rotation_z
from devices.sim.plants import PlantMesh, make_plant, settle_on_ground
from devices.sim.render import Renderer, SensorModel
from devices.sim.scene import Body, PlantTruth, Scene
from devices.sim.soil import SOIL_IR, SOIL_RGB

TRAY_RADIUS_M = 0.17
TRAY_DEPTH_M = 0.06
PLATTER_RADIUS_M = 0.20
PLATTER_THICKNESS_M = 0.03
BENCH_TOP_M = -(TRAY_DEPTH_M + PLATTER_THICKNESS_M)
FLOOR_M = BENCH_TOP_M - 0.72
WORKING_RADIUS_M = 0.30
"""The volume around the axis the plant may occupy (what a turntable session declares)."""


@dataclass(frozen=True)
class TurntableRig:
    """Where the fixed camera stands (``distance_m`` from the axis, ``height_m`` above the
    tray, aimed at ``aim_height_m`` on the axis), the table's step and its stopping error
    (standard deviation of the angle really reached, degrees)."""

    distance_m: float = 1.0
    height_m: float = 0.55
    aim_height_m: float = 0.12
    views: int = 8
    angle_sigma_deg: float = 0.8

    @property
    def view_step_deg(self) -> float:
        return 360.0 / self.views

    @property
    def T_table_camera(self) -> Matrix4:
        """The camera in the table frame (OpenCV axes: x right, y down, z forward)."""
        eye = np.array([0.0, -self.distance_m, self.height_m])
        forward = np.array([0.0, 0.0, self.aim_height_m]) - eye
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        return make_transform(np.column_stack([right, down, forward]), eye)

    def T_view_next(self) -> Matrix4:
        """The nominal ``view_step.matrix``: the plant turning by +step (counter-clockwise seen
        from above) is the camera orbiting the axis by -step, in the plant's frame."""
        C = self.T_table_camera
        turn = make_transform(rotation_z(-self.view_step_deg), np.zeros(3))
        return np.linalg.inv(C) @ turn @ C


def box(
    name: str, low: tuple[float, float, float], high: tuple[float, float, float], rgb: float
) -> Body:
    """An axis-aligned box from corner ``low`` to ``high`` (m), one grey level ``rgb``."""
    corners = np.array(
        [
            [(low, high)[i][0], (low, high)[j][1], (low, high)[k][2]]
            for i in (0, 1)
            for j in (0, 1)
            for k in (0, 1)
        ],
        np.float64,
    )
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = np.array([t for a, b, c, d in faces for t in ((a, b, c), (a, c, d))], np.int32)
    return _uniform_body(name, "wall", corners, triangles, (rgb, rgb, rgb * 0.95), 0.6)


def cylinder(
    name: str,
    radius_m: float,
    z_low_m: float,
    z_high_m: float,
    rgb: tuple[float, ...],
    ir: float,
    sides: int = 96,
) -> Body:
    """A closed cylinder about the z axis."""
    angles = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    ring = np.column_stack([radius_m * np.cos(angles), radius_m * np.sin(angles)])
    vertices = np.concatenate(
        [
            np.column_stack([ring, np.full(sides, z_low_m)]),
            np.column_stack([ring, np.full(sides, z_high_m)]),
            [[0.0, 0.0, z_low_m], [0.0, 0.0, z_high_m]],
        ]
    )
    i = np.arange(sides)
    j = (i + 1) % sides
    bottom, top = 2 * sides, 2 * sides + 1
    triangles = np.concatenate(
        [
            np.column_stack([i, j, j + sides]),
            np.column_stack([i, j + sides, i + sides]),
            np.column_stack([np.full(sides, bottom), j, i]),
            np.column_stack([np.full(sides, top), i + sides, j + sides]),
        ]
    ).astype(np.int32)
    return _uniform_body(name, "wall", vertices, triangles, rgb, ir)


def _uniform_body(
    name: str,
    kind: str,
    vertices: NDArray[np.float64],
    triangles: NDArray[np.int32],
    rgb: tuple[float, ...],
    ir: float,
) -> Body:
    n = len(vertices)
    return Body(
        name,
        "soil" if kind == "soil" else "wall",
        vertices,
        triangles,
        np.tile(np.array(rgb, np.float32), (n, 1)),
        np.full(n, ir, np.float32),
    )


def room_bodies() -> list[Body]:
    """What does not turn: floor, back and side walls, the bench, a cabinet, a box on the bench
    just outside the working volume."""
    return [
        box("floor", (-2.5, -2.0, FLOOR_M - 0.05), (2.5, 3.0, FLOOR_M), 0.45),
        box("back-wall", (-2.5, 1.05, FLOOR_M), (2.5, 1.15, FLOOR_M + 2.6), 0.8),
        box("side-wall", (-1.25, -2.0, FLOOR_M), (-1.15, 1.05, FLOOR_M + 2.6), 0.75),
        box("bench", (-0.7, -0.45, FLOOR_M), (0.7, 0.45, BENCH_TOP_M), 0.5),
        box("cabinet", (-0.95, 0.45, FLOOR_M), (-0.45, 0.95, 0.45), 0.35),
        box("box", (0.40, -0.15, BENCH_TOP_M), (0.62, 0.20, 0.18), 0.6),
    ]


def turning_bodies(plant: PlantMesh) -> list[Body]:
    """What turns with the table: the platter, the tray of soil and the plant."""
    platter_low = BENCH_TOP_M
    soil = cylinder(
        "tray", TRAY_RADIUS_M, -TRAY_DEPTH_M, 0.0, tuple(float(c) for c in SOIL_RGB), SOIL_IR
    )
    soil.kind = "soil"
    return [
        cylinder("platter", PLATTER_RADIUS_M, platter_low, -TRAY_DEPTH_M, (0.2, 0.2, 0.2), 0.5),
        soil,
        Body(
            "plant", "plant", plant.vertices_m, plant.triangles, plant.albedo_rgb, plant.albedo_ir
        ),
    ]


def turntable_plant(seed: int, day: int) -> PlantMesh:
    """The plant of ``seed`` on ``day``, its stem a few cm off the axis (nobody centres a pot
    exactly), settled on the flat soil of the tray."""
    rng = np.random.default_rng([seed, 23])
    radius, azimuth = rng.uniform(0.01, 0.04), rng.uniform(0.0, 2 * np.pi)
    xy = (radius * np.cos(azimuth), radius * np.sin(azimuth))
    mesh = make_plant(seed * 1000 + 500, day, xy, 0.0)
    return settle_on_ground(mesh, np.zeros(len(mesh.vertices_m)))


def _turned(body: Body, angle_deg: float) -> Body:
    R = rotation_z(angle_deg)
    return Body(
        body.name, body.kind, body.vertices_m @ R.T, body.triangles, body.albedo_rgb, body.albedo_ir
    )


@dataclass(frozen=True)
class TurntableCapture:
    """One view: the angle the table reported (the commanded one) and really reached, and what
    the camera saw."""

    view: int
    reported_angle_deg: float
    true_angle_deg: float
    frame: Frame


def turntable_captures(
    plant: PlantMesh,
    rig: TurntableRig,
    views: list[int],
    seed: int,
    intrinsics: Intrinsics = KINECT_V2_PAPER,
    sensor: SensorModel | None = None,
) -> Iterator[TurntableCapture]:
    """Turn the plant through ``views`` and capture each from the fixed camera."""
    rng = np.random.default_rng([seed, 29])
    errors = rng.normal(0.0, rig.angle_sigma_deg, rig.views)
    errors[0] = 0.0  # the table is homed at view 0
    room, turning = room_bodies(), turning_bodies(plant)
    for view in views:
        commanded = view * rig.view_step_deg
        true = commanded + float(errors[view])
        scene = Scene(soil=None, bodies=room + [_turned(b, true) for b in turning])
        renderer = Renderer(scene, intrinsics, sensor)
        frame = renderer.render(rig.T_table_camera, np.random.default_rng([seed, 31, view]))
        yield TurntableCapture(view, commanded, true, frame)


def plant_truth(plant: PlantMesh) -> PlantTruth:
    """The plant's base and traits in the table frame at angle 0."""
    x, y, z = (float(v) for v in plant.base_m)
    return PlantTruth("p01", x, y, z, 100 * plant.height_m, 100 * plant.width_m)
