"""Reading a session's captures into station scans: depth to points and every view into view 0
(Eq. 9), filtering early.

Excess green is computed on the colour images, before any point exists: Otsu's threshold over
all the station's measured pixels, then only the green pixels (and a sparse grid of the others,
for the ground) are back-projected. A seedling plot is mostly soil, so this is where the cloud
shrinks by an order of magnitude.
"""

from __future__ import annotations

import logging
from collections import defaultdict
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4
from fieldapp.errors import FieldappError, FormatError
from fieldapp.io.session import Capture, CaptureImages, Session
from fieldapp.recon.backproject import backproject
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.depth_only import read_scan_capture
from fieldapp.recon.filters import (
    BY_COLOUR,
    Separation,
    choose_separation,
    excess_green,
    keep_soil,
    otsu_threshold,
)
from fieldapp.recon.settings import CropSettings
from fieldapp.recon.station import T_view0_view, station_cloud

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StationScan:
    """One station's views joined in its view-0 camera frame: the green points, a sparse grid
    of the other points (soil, for the ground), and what the excess-green test kept. When the
    plants are separated by geometry (``separation``), ``green`` holds every point and
    ``soil`` the whole sparse grid."""

    station: int
    green: Cloud
    soil: Cloud
    views: list[int]
    exg_threshold: float
    measured_pixels: int
    separation: Separation = BY_COLOUR


def captures_by_station(session: Session) -> dict[int, list[Capture]]:
    """The scan captures (not calibration-board ones) of each station, by view."""
    grouped: dict[int, list[Capture]] = defaultdict(list)
    for capture in session.captures:
        if getattr(capture, "target", None) is None:
            grouped[capture.station].append(capture)
    return {s: sorted(c, key=lambda c: c.view) for s, c in sorted(grouped.items())}


def turntable_axis_point(T_view_next: Matrix4, views: int) -> NDArray[np.float64]:
    """(3,) a point on the turntable axis in view-0 frame: the mean camera centre of a turn."""
    centres = [T_view0_view(T_view_next, view)[:3, 3] for view in range(max(views, 1))]
    return np.mean(centres, axis=0)  # type: ignore[no-any-return]


def read_images(
    session: Session, station: int, captures: list[Capture]
) -> tuple[list[CaptureImages], list[str]]:
    """The images of every readable capture, and one warning per capture skipped."""
    images, warnings = [], []
    for capture in captures:
        try:
            images.append(read_scan_capture(session, capture))
        except FormatError as error:
            warnings.append(f"station {station} view {capture.view} skipped: {error}")
    return images, warnings


def _soil_grid(shape: tuple[int, ...], stride: int) -> NDArray[np.bool_]:
    grid = np.zeros(shape[:2], dtype=bool)
    grid[::stride, ::stride] = True
    return grid


def read_station(
    session: Session,
    station: int,
    captures: list[Capture],
    crop: CropSettings,
    exg_threshold: float | Literal["otsu"],
    soil_pixel_stride: int,
    rays: NDArray[np.float64],
) -> tuple[StationScan | None, list[str]]:
    """Back-project the green pixels (and a sparse grid of the rest, every
    ``soil_pixel_stride``-th pixel) of every readable capture of ``station`` and join them in
    view 0; ``None`` when nothing was readable. ``rays``: the calibration's (H, W, 3) ray
    table. Returns the scan and the warnings (one per capture skipped)."""
    view_step = session.calibration.view_step
    if view_step is None:
        raise FieldappError(f"{session.folder}: the calibration has no view_step")
    images, warnings = read_images(session, station, captures)
    if not images:
        return None, warnings
    measured = [np.isfinite(i.depth_m) for i in images]
    exg = [excess_green(i.color.reshape(-1, 3)).reshape(i.depth_m.shape) for i in images]
    measured_exg = np.concatenate([e[m] for e, m in zip(exg, measured, strict=True)])
    has_colour = all(i.capture.color is not None for i in images)
    separation = choose_separation(measured_exg if has_colour else None)
    threshold = _threshold(measured_exg, exg_threshold) if not separation.by_geometry else np.inf
    separation = keep_soil(separation, measured_exg, threshold)
    threshold = np.inf if separation.by_geometry else threshold
    grid = _soil_grid(images[0].depth_m.shape, soil_pixel_stride)
    green: dict[int, Cloud] = {}
    soil: dict[int, Cloud] = {}
    for image, image_exg in zip(images, exg, strict=True):
        is_green = np.ones_like(grid) if separation.by_geometry else image_exg > threshold
        view = image.capture.view
        green[view] = backproject(
            image.depth_m, image.color, rays, crop.radius_m, crop.min_depth_m, is_green
        )
        soil[view] = backproject(
            image.depth_m,
            image.color,
            rays,
            crop.radius_m,
            crop.min_depth_m,
            grid if separation.by_geometry else grid & ~is_green,
        )
    scan = StationScan(
        station,
        station_cloud(green, view_step.matrix),
        station_cloud(soil, view_step.matrix),
        sorted(green),
        threshold,
        int(sum(int(m.sum()) for m in measured)),
        separation,
    )
    return scan, warnings


def _threshold(exg: NDArray[np.float64], exg_threshold: float | Literal["otsu"]) -> float:
    if exg_threshold == "otsu":
        return otsu_threshold(exg) if len(exg) else 0.0
    return float(exg_threshold)
