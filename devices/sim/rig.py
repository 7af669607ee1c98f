"""The rig: a Kinect v2 on an arm of a turntable on a mobile base, and where it stands.

Frames (``T_a_b`` maps b into a):

- **field**: z up, z = 0 on the mean ground, origin at the plot centre.
- **map**: the base's navigation frame, z up, origin at station 1, axes along the field's:
  ``T_field_map`` is a translation by ``(-spacing, -spacing, 0)``, so station 5 (the centre) is
  at map ``(1.6, 1.6)`` as in the base protocol's example.
- **base**: on the ground under the table axis, x forward; it tilts with the soil.
- **table**: the turntable top, rotated by the table angle about the base's z axis
  (counter-clockwise seen from above, as Grbl's positive X turns it).
- **camera**: OpenCV (x right, y down, z forward), on the arm: ``arm_m`` out from the axis along
  the table's x, ``side_m`` to its left, pitched down by ``pitch_deg``.

Stations 1..G^2 form a G x G grid (``RigGeometry.grid``, 3 by default) numbered row by row
(rows along +y, columns along +x); the reference station is the centre one (5 on the 3 x 3
plan), at the field origin for odd G.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert, make_transform, rotation_z
from devices.sim.soil import Soil

STATIONS = tuple(range(1, 10))
REFERENCE_STATION = 5
MAX_GRID = 9
MAX_TABLE_ERROR_DEG = 3.0
"""The furthest a simulated table may be asked to stop off its target (``--table-error``)."""


@dataclass(frozen=True)
class Pose2D:
    """A base pose in the map frame: metres and degrees."""

    x_m: float
    y_m: float
    yaw_deg: float


@dataclass(frozen=True)
class RigGeometry:
    """Dimensions of the rig. The camera's optical centre is ``camera_height_m`` above the
    ground under the table axis when the base stands level."""

    camera_height_m: float = 1.30
    pitch_deg: float = 45.0
    arm_m: float = 0.20
    side_m: float = 0.03
    views: int = 8
    station_spacing_m: float = 1.6
    wheelbase_m: float = 0.5
    grid: int = 3
    max_tilt_deg: float = 0.0
    """Rough ground under the wheels: at each stop every wheel stands on a clod or in a rut,
    up or down by as much as tilts the base this far about each axis at most (uniform, drawn
    per stop from ``tilt_seed`` and where it stopped), on top of the soil's own slope. 0: the
    soil's slope alone (a degree or less on the simulated soil)."""
    tilt_seed: int = 0

    def __post_init__(self) -> None:
        if not 2 <= self.grid <= MAX_GRID:
            raise ValueError(f"grid must be 2..{MAX_GRID} stations a side, got {self.grid}")

    @property
    def view_step_deg(self) -> float:
        return 360.0 / self.views

    @property
    def stations(self) -> tuple[int, ...]:
        """The station numbers, 1..grid^2."""
        return tuple(range(1, self.grid**2 + 1))

    @property
    def reference_station(self) -> int:
        """The centre station (the lower-numbered middle one on an even grid)."""
        middle = (self.grid - 1) // 2
        return middle * self.grid + middle + 1

    @property
    def plot_half_extent_m(self) -> float:
        """Half the side of the square the stations span (the field origin at its centre)."""
        return (self.grid - 1) * self.station_spacing_m / 2

    @property
    def T_field_map(self) -> Matrix4:
        offset = -self.plot_half_extent_m
        return make_transform(np.eye(3), np.array([offset, offset, 0.0]))

    def station_pose(self, station: int) -> Pose2D:
        """Nominal map pose of ``station`` (1..grid^2): yaw 0, on the G x G grid."""
        if station not in self.stations:
            raise ValueError(f"station must be 1..{self.grid**2}, got {station}")
        row, col = divmod(station - 1, self.grid)
        return Pose2D(col * self.station_spacing_m, row * self.station_spacing_m, 0.0)

    def T_table_camera(self) -> Matrix4:
        """The camera on its arm, in the turntable frame."""
        pitch = np.radians(self.pitch_deg)
        forward = np.array([np.cos(pitch), 0.0, -np.sin(pitch)])
        right = np.array([0.0, -1.0, 0.0])
        down = np.cross(forward, right)
        R = np.stack([right, down, forward], axis=1)
        return make_transform(R, np.array([self.arm_m, self.side_m, self.camera_height_m]))

    def T_camera0_camera(self, table_angle_deg: float) -> Matrix4:
        """Maps the camera at ``table_angle_deg`` into the camera at angle 0 (same base pose).

        ``T_camera0_camera(view_step_deg)`` is the calibration's ``view_step.matrix``."""
        T_table_camera = self.T_table_camera()
        turn = make_transform(rotation_z(table_angle_deg), np.zeros(3))
        return invert(T_table_camera) @ turn @ T_table_camera

    def T_field_base(self, pose: Pose2D, soil: Soil | None = None) -> Matrix4:
        """The base in the field frame. With ``soil``, it stands on it: height and tilt follow
        the ground under its wheels; without, it stands level on z = 0 (the nominal pose)."""
        T_map_base = make_transform(rotation_z(pose.yaw_deg), np.array([pose.x_m, pose.y_m, 0.0]))
        T = self.T_field_map @ T_map_base
        if soil is not None:
            T = T @ _settle(T, soil, self.wheelbase_m, self._wheel_bumps_m(pose))
        return T

    def _wheel_bumps_m(self, pose: Pose2D) -> NDArray[np.float64]:
        """(4,) how far each wheel (front, back, left, right) stands above the soil's surface
        where the base stopped at ``pose`` (:attr:`max_tilt_deg`)."""
        if self.max_tilt_deg <= 0.0:
            return np.zeros(4)
        where = (self.tilt_seed, round(pose.x_m * 1000), round(pose.y_m * 1000))
        rng = np.random.default_rng([abs(v) for v in where] + [int(v < 0) for v in where])
        bump = self.wheelbase_m * np.tan(np.radians(self.max_tilt_deg)) / 2
        bumps: NDArray[np.float64] = rng.uniform(-bump, bump, 4)
        return bumps

    def T_field_camera(
        self, pose: Pose2D, table_angle_deg: float, soil: Soil | None = None
    ) -> Matrix4:
        """The camera in the field frame for a base pose (map) and table angle."""
        turn = make_transform(rotation_z(table_angle_deg), np.zeros(3))
        return self.T_field_base(pose, soil) @ turn @ self.T_table_camera()


def _settle(
    T_field_base: Matrix4,
    soil: Soil,
    wheelbase_m: float,
    bumps_m: NDArray[np.float64],
) -> Matrix4:
    """``T_level_settled``: the base lifted to the ground and tilted to its local slope, each
    wheel (front, back, left, right) ``bumps_m`` above the soil's surface."""
    half = wheelbase_m / 2
    local = np.array([[half, 0, 0], [-half, 0, 0], [0, half, 0], [0, -half, 0], [0, 0, 0.0]])
    points = local @ T_field_base[:3, :3].T + T_field_base[:3, 3]
    z = soil.height_m(points[:, 0], points[:, 1]) + np.r_[bumps_m, 0.0]
    slope_x = (z[0] - z[1]) / wheelbase_m
    slope_y = (z[2] - z[3]) / wheelbase_m
    normal = np.array([-slope_x, -slope_y, 1.0])
    normal /= np.linalg.norm(normal)
    x_axis = np.array([1.0, 0.0, 0.0]) - normal * normal[0]
    x_axis /= np.linalg.norm(x_axis)
    R = np.stack([x_axis, np.cross(normal, x_axis), normal], axis=1)
    return make_transform(R, np.array([0.0, 0.0, float(z[:4].mean())]))


@dataclass(frozen=True)
class StopErrors:
    """How far devices stop from their targets (standard deviations, seeded draws).

    The base's navigation stops within its goal tolerance of the goal by its own estimate
    (``stop_*``) and its estimate is itself off by the localisation error (``locate_*``); the
    table's stepper ends a few hundredths of a degree from its target (backlash, worm gear)."""

    stop_m: float = 0.02
    stop_deg: float = 0.8
    locate_m: float = 0.015
    locate_deg: float = 0.6
    table_deg: float = 0.03
    table_max_deg: float = 0.1
    table_reports_reached: bool = False
    """The table reports the angle it reached (an encoder), not its target (open-loop steps)."""

    @classmethod
    def arrival(cls, sigma_m: float, sigma_deg: float) -> StopErrors:
        """Errors whose true arrival (goal to true pose) has standard deviation ``sigma_m`` per
        horizontal axis and ``sigma_deg`` in yaw, split between stopping and localisation as in
        the defaults (0.8 : 0.6 of the standard deviation)."""
        if sigma_m < 0 or sigma_deg < 0:
            raise ValueError("arrival errors must not be negative")
        return cls(0.8 * sigma_m, 0.8 * sigma_deg, 0.6 * sigma_m, 0.6 * sigma_deg)

    def base_stop(self, goal: Pose2D, rng: np.random.Generator) -> tuple[Pose2D, Pose2D]:
        """(reported, true) poses of the base after driving to ``goal``."""
        reported = _jitter(goal, self.stop_m, self.stop_deg, rng)
        return reported, _jitter(reported, self.locate_m, self.locate_deg, rng)

    @classmethod
    def table(cls, max_deg: float, base: StopErrors | None = None) -> StopErrors:
        """``base``'s errors with a table that stops up to ``max_deg`` off its target (standard
        deviation half that) and reports the angle it reached, as a table with an encoder
        does (a loaded or slipping table, a recorder that writes the angle it measured)."""
        if not 0.0 <= max_deg <= MAX_TABLE_ERROR_DEG:
            raise ValueError(f"table error must be within 0..{MAX_TABLE_ERROR_DEG:g} degrees")
        return replace(
            base or cls(), table_deg=max_deg / 2, table_max_deg=max_deg, table_reports_reached=True
        )

    def table_stop(self, target_deg: float, rng: np.random.Generator) -> float:
        """True angle the table reached when it is sent to ``target_deg``."""
        off = np.clip(rng.normal(0.0, self.table_deg), -self.table_max_deg, self.table_max_deg)
        return float(target_deg + off)

    def table_report(self, target_deg: float, true_deg: float) -> float:
        """The angle the table reports when sent to ``target_deg`` and stopped at
        ``true_deg``."""
        return true_deg if self.table_reports_reached else target_deg


def _jitter(pose: Pose2D, sigma_m: float, sigma_deg: float, rng: np.random.Generator) -> Pose2D:
    dx, dy = np.clip(rng.normal(0.0, sigma_m, 2), -3 * sigma_m, 3 * sigma_m)
    dyaw = float(np.clip(rng.normal(0.0, sigma_deg), -3 * sigma_deg, 3 * sigma_deg))
    return Pose2D(pose.x_m + float(dx), pose.y_m + float(dy), pose.yaw_deg + dyaw)


def camera_position_m(T_field_camera: Matrix4) -> NDArray[np.float64]:
    """(3,) the optical centre in the field frame."""
    return T_field_camera[:3, 3].copy()
