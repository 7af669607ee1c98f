"""Capture quality of one frame: the go/no-go before a mission captures a view.

- **fill rate**: valid depth within the crop radius. The crop region is where the camera sees
  surfaces within ``crop_radius_m`` (the reconstruction keeps only those): the valid pixels
  in range, closed morphologically and with enclosed holes filled, so dropouts inside the
  region count as missing while the far field and the sky do not count at all.
  ``crop_fraction`` says how much of the image that region is (a covered lens gives 0).
- **flying-pixel ratio**: valid pixels in the crop region that lie between the two sides of a
  depth edge, off both (mixed pixels), along rows or columns.
- **over/under-exposed colour**: pixels with a channel at ``overexposed_level`` or above, or
  all channels at ``underexposed_level`` or below.
- **frame age**: now minus the frame's timestamp (monotonic seconds).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import Frame, Intrinsics


@dataclass(frozen=True)
class QualityThresholds:
    """Limits of a usable frame, and the parameters of the measures."""

    crop_radius_m: float = 2.25
    min_fill_rate: float = 0.85
    min_crop_fraction: float = 0.2
    max_flying_ratio: float = 0.03
    max_overexposed: float = 0.05
    max_underexposed: float = 0.20
    max_age_s: float = 0.5
    edge_jump: float = 0.04
    """Relative depth jump between a pixel's two neighbours that makes a depth edge."""
    off_surface: float = 0.01
    """Relative distance from both neighbours that makes an edge pixel a mixed pixel."""
    overexposed_level: int = 250
    underexposed_level: int = 8
    close_px: int = 9
    """Side of the square closing the crop region (fills dropout gaps up to this size)."""


@dataclass(frozen=True)
class QualityReport:
    """The measures of one frame (fractions 0-1, age in seconds)."""

    fill_rate: float
    crop_fraction: float
    flying_ratio: float
    overexposed: float
    underexposed: float
    age_s: float

    def problems(self, limits: QualityThresholds) -> list[str]:
        """What makes the frame unusable, one line each; empty when it is usable."""
        checks = [
            (self.crop_fraction < limits.min_crop_fraction, "crop region", self.crop_fraction,
             f">= {limits.min_crop_fraction:.0%} of the image"),
            (self.fill_rate < limits.min_fill_rate, "depth fill rate", self.fill_rate,
             f">= {limits.min_fill_rate:.0%}"),
            (self.flying_ratio > limits.max_flying_ratio, "flying pixels", self.flying_ratio,
             f"<= {limits.max_flying_ratio:.1%}"),
            (self.overexposed > limits.max_overexposed, "over-exposed colour", self.overexposed,
             f"<= {limits.max_overexposed:.0%}"),
            (self.underexposed > limits.max_underexposed, "under-exposed colour",
             self.underexposed, f"<= {limits.max_underexposed:.0%}"),
        ]  # fmt: skip
        lines = [f"{name} {value:.1%}, needs {need}" for bad, name, value, need in checks if bad]
        if self.age_s > limits.max_age_s:
            lines.append(f"frame is {self.age_s:.2f} s old, needs <= {limits.max_age_s:.2f} s")
        return lines

    def ok(self, limits: QualityThresholds) -> bool:
        return not self.problems(limits)


def range_m(depth_m: NDArray[np.float32], intrinsics: Intrinsics) -> NDArray[np.float32]:
    """(H, W) distance from the optical centre of each pixel's point (NaN where missing)."""
    v, u = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width].astype(np.float32)
    x = (u - intrinsics.cx) / intrinsics.fx
    y = (v - intrinsics.cy) / intrinsics.fy
    distance: NDArray[np.float32] = (depth_m * np.sqrt(1.0 + x * x + y * y)).astype(np.float32)
    return distance


def crop_region(
    depth_m: NDArray[np.float32], intrinsics: Intrinsics, limits: QualityThresholds
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(in range: valid pixels within the radius, region: those closed, holes filled)."""
    import cv2  # here, not at the top: importing it costs the GUI's start-up

    with np.errstate(invalid="ignore"):
        near = np.asarray(range_m(depth_m, intrinsics) <= limits.crop_radius_m)
    mask = near.astype(np.uint8)
    kernel = np.ones((limits.close_px, limits.close_px), np.uint8)
    closed = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)
    outside = np.ascontiguousarray(np.pad(1 - closed, 1, constant_values=1))
    cv2.floodFill(outside, None, (0, 0), 2)  # what stays 1 is enclosed by the region
    region = (closed > 0) | (outside[1:-1, 1:-1] == 1)
    return near, region


def flying_pixels(depth_m: NDArray[np.float32], limits: QualityThresholds) -> NDArray[np.bool_]:
    """(H, W) pixels lying between the two sides of a depth edge, off both of them."""
    flying = np.zeros(depth_m.shape, bool)
    centre = depth_m[1:-1, 1:-1]
    pairs = (
        (depth_m[1:-1, :-2], depth_m[1:-1, 2:]),
        (depth_m[:-2, 1:-1], depth_m[2:, 1:-1]),
    )
    with np.errstate(invalid="ignore"):
        for before, after in pairs:
            edge = np.abs(after - before) > limits.edge_jump * centre
            low, high = np.minimum(before, after), np.maximum(before, after)
            tolerance = limits.off_surface * centre
            between = (centre > low + tolerance) & (centre < high - tolerance)
            flying[1:-1, 1:-1] |= edge & between
    return flying


def assess(
    frame: Frame,
    intrinsics: Intrinsics,
    limits: QualityThresholds | None = None,
    now_s: float | None = None,
) -> QualityReport:
    """Measure ``frame`` (see the module's docstring)."""
    limits = limits or QualityThresholds()
    near, region = crop_region(frame.depth_m, intrinsics, limits)
    region_px = int(region.sum())
    flying = flying_pixels(frame.depth_m, limits) & near
    near_px = int(near.sum())
    color = frame.color
    over = np.any(color >= limits.overexposed_level, axis=2)
    under = np.all(color <= limits.underexposed_level, axis=2)
    now_s = time.monotonic() if now_s is None else now_s
    return QualityReport(
        fill_rate=near_px / region_px if region_px else 0.0,
        crop_fraction=region_px / region.size,
        flying_ratio=int(flying.sum()) / near_px if near_px else 0.0,
        overexposed=float(over.mean()),
        underexposed=float(under.mean()),
        age_s=max(0.0, now_s - frame.timestamp_s),
    )
