"""The simulated Kinect v2: frames of the :class:`~devices.sim.world.SimWorld` as seen from the
rig's current state (base pose and table angle, set by the simulated base and table).

Real time (``realtime=True``) delivers frames on a 30 fps clock like the sensor; a frame
whose tick has passed while the camera was busy is skipped and counted (``frame_number``
jumps), as a real sensor's frames are lost when nobody reads them. Without real time, frames
come as fast as they are made (tests, benchmarks).

Rendering one frame by ray casting takes longer than 33 ms, so by default the camera renders
each rig pose once without noise and draws fresh sensor noise for every frame
(:mod:`devices.camera.sim_noise`); a pose change costs one render (about half a second on
two cores), during which the clock's ticks are skipped. ``fresh_renders=True`` renders every
frame in full with the simulator's own sensor model instead (slow, for fidelity checks).
"""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from devices.camera.base import CameraDisconnected, CameraInfo, DepthCamera
from devices.camera.frames import Frame, Intrinsics
from devices.camera.sim_noise import CleanView, prepare, renoise
from devices.sim.render import Renderer
from devices.sim.rig import Pose2D
from devices.sim.world import SimWorld

log = logging.getLogger(__name__)

KINECT_FPS = 30.0


class SimCamera(DepthCamera):
    """A simulated Kinect v2 looking at ``world`` from the rig's current state."""

    def __init__(
        self,
        world: SimWorld,
        realtime: bool = False,
        fps: float = KINECT_FPS,
        fresh_renders: bool = False,
        seed: int = 0,
        serial: str = "SIM-KINECT2-0001",
    ) -> None:
        super().__init__()
        if fps <= 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.world = world
        self.realtime = realtime
        self.period_s = 1.0 / fps
        self.fresh_renders = fresh_renders
        self._serial = serial
        self._rng = np.random.default_rng([seed, 23])
        self._clean_renderer: Renderer | None = None
        self._view: CleanView | None = None
        self._view_state: tuple[Pose2D, float] | None = None
        self._start_s = 0.0
        self._tick = -1
        self.renders = 0
        """How many times the scene was ray cast (pose changes, or every frame when fresh)."""

    @property
    def intrinsics(self) -> Intrinsics:
        return self.world.intrinsics

    @property
    def info(self) -> CameraInfo:
        return CameraInfo("sim", "Kinect v2 (simulated)", self._serial, simulated=True)

    def _open(self) -> None:
        sensor = dataclasses.replace(self.world.renderer.sensor, noise=False)
        self._clean_renderer = Renderer(self.world.scene, self.world.intrinsics, sensor)
        self._start_s = time.monotonic()
        self._tick = -1
        self._view, self._view_state = None, None
        log.info("simulated Kinect v2 open (%s)", "real time" if self.realtime else "fast")

    def _close(self) -> None:
        self._clean_renderer = None
        self._view, self._view_state = None, None

    def _read(self, timeout_s: float) -> Frame:
        number = self._wait_tick() if self.realtime else self._tick + 1
        self._tick = number
        stamp = time.monotonic()
        state = (self.world.base_pose(), self.world.table_angle_deg())
        frame = self._render(state) if self.fresh_renders else self._renoised(state)
        frame.timestamp_s = stamp
        pose, angle = state
        frame.meta.update(frame_number=number, table_angle_deg=angle, base_pose=pose)
        return frame

    def _wait_tick(self) -> int:
        """Sleep until the next clock tick after the last frame; returns its number."""
        elapsed = time.monotonic() - self._start_s
        due = max(self._tick + 1, int(np.ceil(elapsed / self.period_s - 1e-9)))
        delay = self._start_s + due * self.period_s - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        return due

    def _render(self, state: tuple[Pose2D, float]) -> Frame:
        self.renders += 1
        rng = np.random.default_rng(self._rng.integers(2**63))
        return self.world.render(rng)

    def _renoised(self, state: tuple[Pose2D, float]) -> Frame:
        view = self._view  # close() may clear it from another thread meanwhile
        if view is None or state != self._view_state:
            view = self._clean_view(state)
            self._view, self._view_state = view, state
        return renoise(view, self.world.renderer.sensor, self._rng)

    def _clean_view(self, state: tuple[Pose2D, float]) -> CleanView:
        renderer = self._clean_renderer
        if renderer is None:  # closed while a grabber was reading
            raise CameraDisconnected("the simulated camera was closed")
        started = time.perf_counter()
        pose, angle = state
        T_field_camera = self.world.rig.T_field_camera(pose, angle, self.world.scene.soil)
        clean = renderer.render(T_field_camera)
        clean.meta["T_field_camera"] = T_field_camera.tolist()
        view = prepare(clean, self.intrinsics, self.world.renderer.sensor)
        self.renders += 1
        log.debug("rendered a new rig pose in %.0f ms", 1000 * (time.perf_counter() - started))
        return view
