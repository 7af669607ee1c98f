"""What every depth camera backend produces: intrinsics and frames."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a depth camera, OpenCV convention (x right, y down, z forward).

    ``distortion`` is OpenCV's k1, k2, p1, p2, k3.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def K(self) -> NDArray[np.float64]:
        """The (3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def has_distortion(self) -> bool:
        return any(abs(c) > 0.0 for c in self.distortion)


KINECT_V2_PAPER = Intrinsics(width=512, height=424, fx=365.18, fy=364.49, cx=256.00, cy=209.59)
KINECT_V2_DISTORTION = (0.09, -0.27, 0.0, 0.0, 0.09)
"""A Kinect v2 depth lens's radial distortion, OpenCV's k1, k2, p1, p2, k3, of the size each
unit's factory calibration reports (libfreenect2 reads the unit's own): a pixel at the image's
corner moves about 10 px."""
"""The Kinect v2 depth camera as the seed paper calibrated it (Zhang, IR images)."""


@dataclass
class Frame:
    """One frame from a depth camera.

    - ``depth_m``: (H, W) float32, depth along the optical axis in metres, NaN where missing.
    - ``color``: (H, W, 3) uint8 RGB, registered to the depth image pixel for pixel.
    - ``ir``: (H, W) uint16 infrared amplitude, or ``None`` when the camera has none.
    - ``timestamp_s``: monotonic time of acquisition, seconds.
    """

    depth_m: NDArray[np.float32]
    color: NDArray[np.uint8]
    ir: NDArray[np.uint16] | None = None
    timestamp_s: float = 0.0
    meta: dict[str, object] = field(default_factory=dict)
