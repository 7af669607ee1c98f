"""Reading a session's captures into station scans: depth to points and every view into view 0
(Eq. 9), filtering early.

Excess green is computed on the colour images, before any point exists: Otsu's threshold over
all the station's measured pixels, then only the green pixels (and a sparse grid of the others,
for the ground) are back-projected. A seedling plot is mostly soil, so this is where the cloud
shrinks by an order of magnitude.
"""

from __future__ import annotations

import ctypes
import logging
import os
from collections import defaultdict
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Literal, TypeVar

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4
from fieldapp.errors import FieldappError, FormatError
from fieldapp.io.session import Capture, CaptureImages, Session
from fieldapp.recon.backproject import backproject_pixels
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

A = TypeVar("A")
B = TypeVar("B")


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
            warnings.append(_skipped(station, capture, error))
    return images, warnings


def _skipped(station: int, capture: Capture, error: FormatError) -> str:
    return f"station {station} view {capture.view} skipped: {error}"


@dataclass(frozen=True)
class ReadFrame:
    """One capture read: its images and the excess green of its measured pixels (finite depth).

    ``images``: as read; ``measured``: (H, W) bool; ``exg``: (M,) float64, the excess green of
    the measured pixels in row-major order (the rest is never used).
    """

    images: CaptureImages
    measured: NDArray[np.bool_]
    exg: NDArray[np.float64]

    @property
    def capture(self) -> Capture:
        return self.images.capture


def frame_of(images: CaptureImages) -> ReadFrame:
    """A capture's images with the excess green of its measured pixels. Computed over the whole
    frame, then picked: cheaper than gathering the measured pixels' colours first."""
    measured = np.isfinite(images.depth_m)
    exg = excess_green(images.color.reshape(-1, 3))[measured.reshape(-1)]
    return ReadFrame(images, measured, exg)


class FrameWorkers:
    """Runs one function over a station's frames on ``threads`` threads (OpenCV's decoding
    and numpy release the interpreter), the results in the frames' order whatever the thread
    count; on the calling thread when ``threads`` is 1."""

    def __init__(self, threads: int) -> None:
        self._pool = ThreadPoolExecutor(threads, "frames") if threads > 1 else None

    def map(self, work: Callable[[A], B], items: Sequence[A]) -> list[B]:
        if self._pool is None or len(items) < 2:
            return [work(item) for item in items]
        return list(self._pool.map(work, items))

    def __enter__(self) -> FrameWorkers:
        return self

    def __exit__(self, *_: object) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            return_freed_memory()


def return_freed_memory() -> None:
    """Give the system back the memory the frame threads freed. glibc keeps it in each
    thread's own malloc arena, where the main thread's later stages cannot reuse it: without
    this, reading the frames on two threads raised a 3 x 3 plot's peak memory by about 20 MB
    (issue 22). Nothing happens where the C library is not glibc."""
    if "glibc" not in (_libc_version() or ""):
        return
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):
        log.debug("malloc_trim is not available")


def _libc_version() -> str | None:
    try:
        return os.confstr("CS_GNU_LIBC_VERSION")
    except (ValueError, OSError):
        return None


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
    threads: int = 1,
) -> tuple[StationScan | None, list[str]]:
    """Back-project the green pixels (and a sparse grid of the rest, every
    ``soil_pixel_stride``-th pixel) of every readable capture of ``station`` and join them in
    view 0; ``None`` when nothing was readable. ``rays``: the calibration's (H, W, 3) ray
    table. Frames are decoded and back-projected on ``threads`` threads; the result does not
    depend on their number. Returns the scan and the warnings (one per capture skipped)."""
    view_step = session.calibration.view_step
    if view_step is None:
        raise FieldappError(f"{session.folder}: the calibration has no view_step")
    with FrameWorkers(threads) as workers:
        read = workers.map(lambda capture: _read_frame(session, station, capture), captures)
        frames = [frame for frame in read if isinstance(frame, ReadFrame)]
        warnings = [warning for warning in read if isinstance(warning, str)]
        if not frames:
            return None, warnings
        separation, threshold = _separation(frames, exg_threshold)
        grid = _soil_grid(frames[0].measured.shape, soil_pixel_stride)
        clouds = workers.map(
            lambda frame: _green_and_soil(frame, separation, threshold, grid, rays, crop), frames
        )
    views = [frame.capture.view for frame in frames]
    scan = StationScan(
        station,
        station_cloud(
            dict(zip(views, (green for green, _ in clouds), strict=True)), view_step.matrix
        ),
        station_cloud(
            dict(zip(views, (soil for _, soil in clouds), strict=True)), view_step.matrix
        ),
        sorted(views),
        threshold,
        sum(len(frame.exg) for frame in frames),
        separation,
    )
    return scan, warnings


def _read_frame(session: Session, station: int, capture: Capture) -> ReadFrame | str:
    """A capture's measured pixels, or the warning saying why it was skipped."""
    try:
        return frame_of(read_scan_capture(session, capture))
    except FormatError as error:
        return _skipped(station, capture, error)


def _separation(
    frames: list[ReadFrame], exg_threshold: float | Literal["otsu"]
) -> tuple[Separation, float]:
    """How the station's plants are told from its soil, and the ExG threshold (infinite by
    geometry), judged on every measured pixel of the station."""
    measured_exg = np.concatenate([frame.exg for frame in frames])
    has_colour = all(frame.capture.color is not None for frame in frames)
    separation = choose_separation(measured_exg if has_colour else None)
    threshold = _threshold(measured_exg, exg_threshold) if not separation.by_geometry else np.inf
    separation = keep_soil(separation, measured_exg, threshold)
    return separation, np.inf if separation.by_geometry else threshold


def _green_and_soil(
    frame: ReadFrame,
    separation: Separation,
    threshold: float,
    grid: NDArray[np.bool_],
    rays: NDArray[np.float64],
    crop: CropSettings,
) -> tuple[Cloud, Cloud]:
    """One frame's green points and its soil sample (the ``grid`` (H, W) pixels not green),
    in its camera frame; by geometry every point is "green" and the soil the whole grid."""
    if frame.measured.shape != rays.shape[:2]:
        raise ValueError(f"depth {frame.measured.shape} does not match the camera {rays.shape[:2]}")
    index = np.flatnonzero(frame.measured)
    on_grid = grid.reshape(-1)[index]
    if separation.by_geometry:
        green, soil = np.ones(len(index), dtype=bool), on_grid
    else:
        green = frame.exg > threshold
        soil = on_grid & ~green

    def cloud(picked: NDArray[np.bool_]) -> Cloud:
        pixels = index[picked]
        depth_m = frame.images.depth_m.reshape(-1)[pixels]
        colors = frame.images.color.reshape(-1, 3)[pixels]
        return backproject_pixels(pixels, depth_m, colors, rays, crop.radius_m, crop.min_depth_m)

    return cloud(green), cloud(soil)


def _threshold(exg: NDArray[np.float64], exg_threshold: float | Literal["otsu"]) -> float:
    if exg_threshold == "otsu":
        return otsu_threshold(exg) if len(exg) else 0.0
    return float(exg_threshold)
