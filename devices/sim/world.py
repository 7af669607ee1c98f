"""The live simulated world: one scene, one rig and the rig's current state, shared by the
simulated base, table and camera.

The base simulator calls :meth:`SimWorld.set_base_pose` with where the base *really* is (map
frame; what it reports may differ, see :class:`~devices.sim.rig.StopErrors`), the table
simulator calls :meth:`SimWorld.set_table_angle_deg` with the angle the table *really* reached,
and the camera simulator calls :meth:`SimWorld.render` to see what the camera sees from there.
All methods are thread-safe.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from devices.camera.frames import KINECT_V2_PAPER, Frame, Intrinsics
from devices.geometry import Matrix4
from devices.sim.render import Renderer, SensorModel
from devices.sim.rig import Pose2D, RigGeometry
from devices.sim.scene import Scene, plot_scene
from devices.sim.visibility import boards_in_view

log = logging.getLogger(__name__)


class SimWorld:
    """A scene seen by the rig's Kinect v2 from the current base pose and table angle.

    The rig starts at the reference station (5 on the 3 x 3 plan) with the table at 0 degrees.
    """

    def __init__(
        self,
        scene: Scene,
        rig: RigGeometry | None = None,
        intrinsics: Intrinsics = KINECT_V2_PAPER,
        sensor: SensorModel | None = None,
        seed: int = 0,
    ) -> None:
        self.scene = scene
        self.rig = rig or RigGeometry()
        self.renderer = Renderer(scene, intrinsics, sensor)
        self._lock = threading.Lock()
        self._base_pose = self.rig.station_pose(self.rig.reference_station)
        self._table_angle_deg = 0.0
        self._rng = np.random.default_rng([seed, 3])

    @classmethod
    def default(cls, seed: int = 0, day: int = 0) -> SimWorld:
        """The embedded default world: the 16-plant plot of ``seed`` on ``day``."""
        return cls(plot_scene(seed, day), seed=seed)

    @property
    def intrinsics(self) -> Intrinsics:
        return self.renderer.intrinsics

    def set_base_pose(self, x_m: float, y_m: float, yaw_deg: float) -> None:
        """Where the base really is now, in the map frame (metres, degrees)."""
        with self._lock:
            self._base_pose = Pose2D(float(x_m), float(y_m), float(yaw_deg))

    def base_pose(self) -> Pose2D:
        with self._lock:
            return self._base_pose

    def set_table_angle_deg(self, angle_deg: float) -> None:
        """The angle the turntable really stands at (degrees, counter-clockwise from above)."""
        with self._lock:
            self._table_angle_deg = float(angle_deg)

    def table_angle_deg(self) -> float:
        with self._lock:
            return self._table_angle_deg

    def T_field_camera(self) -> Matrix4:
        """Where the camera is now, in the field frame (the base standing on the soil)."""
        with self._lock:
            pose, angle = self._base_pose, self._table_angle_deg
        return self.rig.T_field_camera(pose, angle, self.scene.soil)

    def boards_in_view(self) -> list[str]:
        """Names of the scene's boards the camera sees whole from where it is now."""
        return boards_in_view(
            self.scene, self.intrinsics, self.T_field_camera(), self.renderer.raycaster
        )

    def render(self, rng: np.random.Generator | None = None) -> Frame:
        """What the camera sees now; ``meta["T_field_camera"]`` holds the true pose (4 x 4)."""
        T = self.T_field_camera()
        with self._lock:
            rng = rng or np.random.default_rng(self._rng.integers(2**63))
        frame = self.renderer.render(T, rng)
        frame.timestamp_s = time.monotonic()
        frame.meta["T_field_camera"] = T.tolist()
        return frame
