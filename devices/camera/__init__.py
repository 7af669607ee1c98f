"""Depth cameras behind one small interface (frames, intrinsics, capture).

- :mod:`devices.camera.base`: :class:`DepthCamera` and the typed errors.
- :mod:`devices.camera.capture`: quiet captures (per-pixel median of n frames).
- :mod:`devices.camera.stream`: the grabber thread and latest-frame buffer.
- :mod:`devices.camera.quality`: the per-frame go/no-go measures.
- backends: :mod:`~devices.camera.sim`, :mod:`~devices.camera.replay`,
  :mod:`~devices.camera.kinect2`, :mod:`~devices.camera.realsense`, built by
  :func:`devices.camera.factory.make_camera`.
"""

from devices.camera.base import (
    CameraDisconnected,
    CameraEnded,
    CameraError,
    CameraFormatError,
    CameraInfo,
    CameraTimeout,
    CameraUnavailable,
    DepthCamera,
)
from devices.camera.frames import KINECT_V2_PAPER, Frame, Intrinsics

__all__ = [
    "KINECT_V2_PAPER",
    "CameraDisconnected",
    "CameraEnded",
    "CameraError",
    "CameraFormatError",
    "CameraInfo",
    "CameraTimeout",
    "CameraUnavailable",
    "DepthCamera",
    "Frame",
    "Intrinsics",
]
