"""One camera, two readers: the live preview and a mission.

A camera is read by one grabber thread (:class:`~devices.camera.stream.FrameStream`); a second
reader calling ``read_frame`` at the same time would take every other frame from it (a real
Kinect) or race inside the driver (the simulator). :class:`StreamCamera` gives a mission the
:class:`~devices.camera.base.DepthCamera` it expects, served from the stream: each read waits
for a frame acquired after the read began, so a capture after a table move never gets a frame
from before it.
"""

from __future__ import annotations

import time

from devices.camera.base import CameraInfo, CameraTimeout, DepthCamera
from devices.camera.frames import Frame, Intrinsics
from devices.camera.stream import FrameStream


class StreamCamera(DepthCamera):
    """Reads ``stream`` (grabbing from ``camera``); opening and closing leave both alone."""

    def __init__(self, stream: FrameStream) -> None:
        super().__init__()
        self.stream = stream
        self.open()

    @property
    def intrinsics(self) -> Intrinsics:
        return self.stream.camera.intrinsics

    @property
    def info(self) -> CameraInfo:
        return self.stream.camera.info

    def _open(self) -> None:
        """The stream's camera is already open."""

    def _close(self) -> None:
        """The stream and its camera belong to the device hub."""

    def _read(self, timeout_s: float) -> Frame:
        asked_s = time.monotonic()
        deadline_s = asked_s + timeout_s
        while True:
            remaining_s = deadline_s - time.monotonic()
            if remaining_s <= 0:
                raise CameraTimeout(f"no new frame from the camera within {timeout_s:.1f} s")
            frame = self.stream.next_frame(remaining_s)
            if frame.timestamp_s >= asked_s:
                return frame
