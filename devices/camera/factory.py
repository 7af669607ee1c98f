"""One place that builds a camera from a backend name; each backend is imported only when
chosen, so a missing optional library only matters to the backend that needs it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from devices.camera.base import CameraUnavailable, DepthCamera

if TYPE_CHECKING:
    from devices.sim.world import SimWorld

BACKENDS = ("sim", "replay", "kinect2", "realsense")


def make_camera(
    backend: str,
    *,
    world: SimWorld | None = None,
    realtime: bool = True,
    session: Path | None = None,
    loop: bool = False,
    serial: str | None = None,
    recording: Path | None = None,
) -> DepthCamera:
    """A camera of ``backend`` (not yet open).

    - ``sim``: looks at ``world`` (default: the embedded plot), at 30 fps when ``realtime``.
    - ``replay``: plays ``session`` (a session folder), looping when ``loop``, at 30 fps when
      ``realtime``.
    - ``kinect2``, ``realsense``: the device ``serial`` (default: the first found);
      ``recording`` plays a RealSense SDK recording instead of a device.
    """
    if backend == "sim":
        from devices.camera.sim import SimCamera
        from devices.sim.world import SimWorld

        return SimCamera(world or SimWorld.default(), realtime=realtime)
    if backend == "replay":
        from devices.camera.replay import ReplayCamera

        if session is None:
            raise CameraUnavailable("the replay camera needs a session folder to play")
        return ReplayCamera(session, loop=loop, fps=30.0 if realtime else None)
    if backend == "kinect2":
        from devices.camera.kinect2 import Kinect2Camera

        return Kinect2Camera(serial)
    if backend == "realsense":
        from devices.camera.realsense import RealSenseCamera

        return RealSenseCamera(serial, recording=recording)
    raise ValueError(f"unknown camera backend {backend!r}: one of {', '.join(BACKENDS)}")
