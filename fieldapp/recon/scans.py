"""Reading a session's captures into station scans: depth to points and every view into view 0
(Eq. 9), filtering early.

Excess green is computed on the colour images, before any point exists: Otsu's threshold over
all the station's measured pixels, then only the green pixels (and a sparse grid of the others,
for the ground) are back-projected. A seedling plot is mostly soil, so this is where the cloud
shrinks by an order of magnitude. The pixels are tallied by colour key (:func:`exg_keys`), so
the station's threshold is found from a few thousand distinct values, not 1.6 million floats.
"""

from __future__ import annotations

import ctypes
import functools
import logging
import operator
import os
from collections import defaultdict
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Literal, TypeVar

import cv2
import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4
from fieldapp.errors import FieldappError, FormatError
from fieldapp.io.calibration import ViewStep
from fieldapp.io.session import Capture, CaptureImages, Session
from fieldapp.recon.backproject import backproject_pixels, backproject_pixels_twice
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.colour_offset import (
    ColourOffset,
    EdgeContrasts,
    colour_offset,
    edge_contrasts,
    moved_colour,
)
from fieldapp.recon.depth_only import read_scan_capture
from fieldapp.recon.exg import (
    BY_COLOUR,
    NO_KEY,
    NOISE_SIGMAS,
    Separation,
    above_the_soil,
    choose_separation,
    exg_keys,
    exg_of_keys,
    exg_tally,
    exg_values,
    hued,
    keep_soil,
    mixed_pixel_threshold,
    noise_floors,
    otsu_threshold,
    thresholds_by_key,
    uncoloured_keys,
)
from fieldapp.recon.ground import least_squares_plane
from fieldapp.recon.settings import CropSettings
from fieldapp.recon.station import (
    MAX_ANGLE_OFF_DEG,
    T_view0_reached,
    T_view0_view,
    angle_off_deg,
    station_cloud,
)

log = logging.getLogger(__name__)

REGISTRATION_PX = 2
"""How far (pixels) a colour image registered to its depth may be off at a surface's edge:
Kinect v2 registration (libfreenect2, the SDK) is within a pixel or two."""
MIXED_RIM_REACH_PX = 4
"""How far (pixels) from a green pixel a leaf's own surface may have lost its green where a
station's colour is mixed over the leaves' rims (:func:`grown_over_edges`; the valley between
soil and leaves filled with mixed pixels, so :func:`~fieldapp.recon.exg.mixed_pixel_threshold`
cut below Otsu's: JPEG): :data:`REGISTRATION_PX`, and two more for the chroma at half
resolution, which gives the whole of a blade a few pixels wide (a maize seedling's is 1.5-4
cm, 4-10 px at 1.5-2 m) the soil's colour over its last centimetres (RECONSTRUCTION.md,
"Narrow leaf blades"). Where the classes stand apart (PNG) the rim is grown
:data:`REGISTRATION_PX`, as before."""
CONTINUOUS_SHARE = 0.03
"""Neighbouring pixels within this share of their distance lie on one surface: at 2 m, 6 cm
over the two pixels' reach, so a surface seen up to about 75 degrees from face-on is continuous,
and a leaf 5 cm or more above the soil is not continuous with the soil beside it."""
WEAK_SHARE = 0.5
"""A pixel beside green is weakly green when its ExG is past this share of the way from the
soil's mean ExG to the threshold (:func:`grown_into_weak_green`): halfway, the hysteresis an
edge detector's two thresholds make."""
WEAK_REACH_PX = 4
"""How far (pixels) green grows into weak green: a JPEG's chroma is at half resolution in 8 x
8 blocks, so a leaf's colour bleeds over two to four pixels of its edge."""
UNCOLOURED_REACH_PX = 12
"""How far (pixels) green grows into measured pixels without colour
(:func:`grown_into_uncoloured`): the colour camera, 5.2 cm beside the depth camera, loses a
band 365 px x 0.052 m x (1 / near - 1 / far) wide beside a near edge: 8 px for a leaf 30 cm in
front of another 1 m away, 12 px at 0.8 m."""
CONTINUED_REACH_PX = 16
"""How far (pixels) a leaf's surface is followed from its coloured pixels into pixels whose
colour is not green (:func:`continued_surfaces`): a leaf's tip seen at 1.5-2.5 m, whose last
few centimetres (6-12 px at 2 m) take the soil's colour or yellow."""
CONTINUED_MIN_HEIGHT_M = 0.04
"""A pixel is followed only this far above the frame's ground plane (a plane through its soil
sample, :func:`frame_ground_heights`): a leaf lying on the soil continues into the soil, whose
depth runs on without an edge; the levelled station's pass-through then wants
``FilterSettings.pass_through_continued_min_m`` above the local ground."""
CONTINUED_SHARE = 0.03
"""A pixel continues the one beside it within this share of its distance
(:func:`continued_surfaces`)."""
MIN_GROUND_PIXELS = 50
GROUND_SAMPLE = 500
"""A frame with fewer soil sample pixels than the first has no ground plane, and no surface is
followed; the plane is fitted to one to two times the second, evenly spread (a plane needs
few: 0.24 ms a frame, against 0.55 with 2 000)."""
BLOCK_PX = 5
"""Side of the window whose median depth a point takes for the registration
(:func:`block_median_depths`): a soil sample pixel's the block of 4 x 4 pixels it stands for on
the default grid, centred."""
SAME_SURFACE_SIGMAS = 3.0
"""A plant pixel's window takes the depths within this many times the frame's noise of its own
(:func:`block_median_depths`, :func:`noise_per_m2`)."""
MIN_NOISE_PER_M2 = 1e-4
"""The least noise :func:`noise_per_m2` gives: 0.4 mm at 2 m, below any Kinect v2's."""
NOT_MEASURED_M = 1e3
"""The distance given to unmeasured pixels in the image filters (far behind everything)."""

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
    steady: tuple[Cloud, Cloud] | None = None
    """``green`` and ``soil`` again, point for point, each at its block's median depth
    (:func:`block_median_depths`), for the registration and, by geometry, for telling the
    plants from the soil; ``None``: the two themselves (a turntable's scan)."""
    colour_offset: ColourOffset | None = None
    """How far the station's colour was found registered off its depth, and moved back
    (:mod:`fieldapp.recon.colour_offset`); ``None``: not told (no colour, too few depth edges)."""
    continued: Cloud | None = None
    """The points of the leaves' surfaces continued past their green (:func:`continued_surfaces`),
    in the same frame; ``None``: none looked for (a turntable's scan)."""


def captures_by_station(session: Session) -> dict[int, list[Capture]]:
    """The scan captures (not calibration-board ones) of each station, by view."""
    grouped: dict[int, list[Capture]] = defaultdict(list)
    for capture in session.captures:
        if getattr(capture, "target", None) is None:
            grouped[capture.station].append(capture)
    return {s: sorted(c, key=lambda c: c.view) for s, c in sorted(grouped.items())}


def carries_plant(session: Session) -> bool:
    """Whether ``session`` is a plant-on-turntable session."""
    table = session.document.turntable
    return table is not None and table.carries == "plant"


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
    """One capture read: its images, its measured pixels (finite depth) and their colour keys.

    ``images``: as read; ``measured``: (H, W) bool; ``keys``: (H * W,) int32, the
    :func:`~fieldapp.recon.exg.exg_keys` of every pixel in row-major order,
    :data:`~fieldapp.recon.exg.NO_KEY` where none is measured, and ``tally``:
    (EXG_KEYS,) int64, how many measured pixels with colour have each key; both ``None`` for
    a depth-only capture (no colour: its plants are told by geometry). ``measured_pixels``: how
    many are measured, ``uncoloured``: how many of them have no colour (black,
    :data:`~fieldapp.recon.exg.NO_COLOUR_SUM`).
    """

    images: CaptureImages
    measured: NDArray[np.bool_]
    keys: NDArray[np.int32] | None
    tally: NDArray[np.int64] | None
    measured_pixels: int
    uncoloured: int = 0

    @property
    def capture(self) -> Capture:
        return self.images.capture


def frame_of(images: CaptureImages) -> ReadFrame:
    """A capture's images with the colour keys of its measured pixels and their tally."""
    measured = np.isfinite(images.depth_m)
    count = int(np.count_nonzero(measured))
    if images.capture.color is None:
        return ReadFrame(images, measured, None, None, count)
    keys = exg_keys(images.color.reshape(-1, 3))
    keys[~measured.reshape(-1)] = NO_KEY
    tally = exg_tally(keys)
    return ReadFrame(images, measured, keys, tally, count, count - int(tally.sum()))


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


def _soil_grid(shape: tuple[int, ...], stride: int) -> NDArray[np.intp]:
    """(M,) the flat indices, ascending, of every ``stride``-th pixel of every ``stride``-th
    row of an (H, W) image."""
    rows, columns = np.arange(0, shape[0], stride), np.arange(0, shape[1], stride)
    return (rows[:, None] * shape[1] + columns[None, :]).reshape(-1)


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
        frames, offset = _colour_on_depth(frames, workers)
        separation, threshold, weak, rim_px, tally, moved = _separation(frames, exg_threshold)
        if moved is not None:
            warnings.append(
                f"station {station}: Otsu's excess-green threshold {moved:.3f} cut inside the "
                f"soil's colour noise (leaves a sliver of its pixels, noisy colour): "
                f"{threshold:.3f} used, above the soil's spread"
            )
        grid = _soil_grid(frames[0].measured.shape, soil_pixel_stride)
        keys = _green_keys(threshold, weak, tally)
        clouds = workers.map(
            lambda frame: _green_and_soil(frame, separation, keys, rim_px, grid, rays, crop),
            frames,
        )
    views = [frame.capture.view for frame in frames]
    placed = _placed_at_reached_angles(station, frames, view_step, warnings)

    parts: list[list[Cloud | None]] = [list(frame_clouds) for frame_clouds in clouds]
    del clouds

    def joined(part: int) -> Cloud:
        """Part ``part`` of every frame's clouds, joined in view 0, and let go of: each part
        of a depth-only frame is every pixel it measured."""
        by_view = {}
        for view, frame_parts in zip(views, parts, strict=True):
            cloud, frame_parts[part] = frame_parts[part], None
            assert cloud is not None  # each part is joined once
            by_view[view] = cloud
        return station_cloud(by_view, view_step.matrix, placed)

    scan = StationScan(
        station,
        joined(0),
        joined(1),
        sorted(views),
        threshold,
        sum(frame.measured_pixels for frame in frames),
        separation,
        (joined(2), joined(3)),
        offset,
        joined(4),
    )
    return scan, warnings


def _colour_on_depth(
    frames: list[ReadFrame], workers: FrameWorkers
) -> tuple[list[ReadFrame], ColourOffset | None]:
    """The station's frames with their colour moved onto their depth where it was found
    registered off it (:mod:`fieldapp.recon.colour_offset`), and the offset found: one for
    the station's views, which one camera took."""
    coloured = [frame for frame in frames if frame.keys is not None]
    if not coloured:
        return frames, None
    contrasts = functools.reduce(operator.add, workers.map(_edge_contrasts, coloured))
    measured = sum(frame.measured_pixels for frame in coloured)
    uncoloured = sum(frame.uncoloured for frame in coloured) / max(measured, 1)
    offset = colour_offset(contrasts, uncoloured)
    if offset is None or not offset.moved:
        return frames, offset

    def moved(frame: ReadFrame) -> ReadFrame:
        if frame.keys is None:
            return frame
        return frame_of(replace(frame.images, color=moved_colour(frame.images.color, offset)))

    return workers.map(moved, frames), offset


def _edge_contrasts(frame: ReadFrame) -> EdgeContrasts:
    assert frame.keys is not None  # a frame with colour
    return edge_contrasts(frame.keys, frame.images.depth_m, CONTINUOUS_SHARE)


def _placed_at_reached_angles(
    station: int, frames: list[ReadFrame], view_step: ViewStep, warnings: list[str]
) -> dict[int, Matrix4]:
    """Each view whose recorded angle (``angle_deg``) is off its nominal one, placed at the
    angle reached (:func:`station.T_view0_reached`); one warning per view whose angle is too
    far off to be trusted (:data:`station.MAX_ANGLE_OFF_DEG`), which keeps the chain."""
    placed = {}
    for frame in frames:
        view, angle = frame.capture.view, frame.capture.angle_deg
        off = angle_off_deg(view, angle, view_step.angle_deg)
        if abs(off) > MAX_ANGLE_OFF_DEG:
            warnings.append(
                f"station {station} view {view}: angle_deg {angle:g} is {off:+.1f} degrees off "
                f"view {view} x {view_step.angle_deg:g}; placed at the nominal angle"
            )
        elif off != 0.0:
            placed[view] = T_view0_reached(view_step.matrix, view_step.angle_deg, view, off)
    return placed


@functools.cache
def _square(reach_px: int) -> NDArray[np.uint8]:
    """The square of pixels within ``reach_px`` of one (OpenCV's structuring element)."""
    return np.ones((2 * reach_px + 1,) * 2, np.uint8)


_NEIGHBOURS = np.ones((3, 3), np.uint8)
"""A pixel and its eight neighbours: one step of the pixel-by-pixel growths."""


@dataclass(frozen=True)
class DepthEdges:
    """A frame's depth as the colour filters see it: ``far_m`` (H, W) the distance of each
    pixel (:data:`NOT_MEASURED_M` where none is measured) and ``behind`` (H, W) whether a
    nearer surface lies within :data:`REGISTRATION_PX` of it (nearer by more than
    :data:`CONTINUOUS_SHARE` of its distance): computed once for both growth steps."""

    far_m: NDArray[np.float32]
    behind: NDArray[np.bool_]
    measured: NDArray[np.bool_]

    @classmethod
    def of(cls, depth_m: NDArray[np.float32], measured: NDArray[np.bool_]) -> DepthEdges:
        far = np.where(measured, depth_m, NOT_MEASURED_M).astype(np.float32)
        behind = far - cv2.erode(far, _square(REGISTRATION_PX)) > CONTINUOUS_SHARE * far
        return cls(far, behind, measured)


MIXED_SHARE = 0.02
"""How far (share of its distance) a mixed pixel lies from each of the two surfaces beside it
(:func:`mixed_pixels`). A pixel whose neighbours on both sides step away by more than 2 % of
its distance would be, as a surface, seen within 8 degrees of grazing (a Kinect v2 pixel spans
1/365 rad, and 0.02 x 365 = tan 82 degrees from face-on), which a time-of-flight camera does not
measure: it is a pixel in the air on the rays past an edge. Below :data:`CONTINUOUS_SHARE`
because a veil of such pixels steps from a leaf's edge to the surface behind it in as many steps
as it is deep, each a share of the gap: at 3 % the inner pixels of the deeper veils were missed
(on an independent renderer's seedlings the points newly flagged at 2 % lay a median 2.5 cm off
every leaf, 77 % of them more than 1.5 cm off, against 0.8 cm and 15 % for the points left
unflagged; RECONSTRUCTION.md, "A veil's inner pixels"). Lower still, the pixels taken from
1.5 % to 1 % lay within 1.5 cm of a leaf in 41-63 %: leaves seen 10-15 degrees from grazing."""
MIXED_REACH_PX = 1
"""How far (pixels) on each side :func:`mixed_pixels` looks for the two surfaces a mixed pixel
lies between: the pixels beside it. A veil two or more deep is still found where each of its
steps is over :data:`MIXED_SHARE`, while a surface two or more pixels wide between a
nearer and a farther one (a lower leaf's tip seen between an upper leaf and the soil, in
touching canopies) continues itself on one side and is not taken (two pixels on each side
took such tips on an independent renderer's touching plots: widths 0.5-3 cm narrower where its
views had seen them). A veil two deep whose two pixels are within that share of each other
is, in depth alone, such a surface, and is not taken either."""


def mixed_pixels(edges: DepthEdges, pixels: NDArray[np.intp]) -> NDArray[np.bool_]:
    """(P,) which of ``pixels`` (P,) (row-major indices into the frame) lie between two
    surfaces: along a row, a column or a diagonal, a measured pixel within
    :data:`MIXED_REACH_PX` on one side nearer than it and one on the other side farther, each
    by more than :data:`MIXED_SHARE` of its distance.

    A time-of-flight pixel across a depth edge returns a depth between the two surfaces it sees:
    a point in the air between a leaf's edge and the soil or leaf behind it, off every surface
    (a veil of them along the view's rays). A leaf's own edge pixel is continuous with the leaf
    on one side, and a stem or a thin tip seen against the soil has the soil farther on both
    sides: neither is between two surfaces."""
    far = edges.far_m
    height, width = far.shape
    reach = MIXED_REACH_PX
    padded = np.full((height + 2 * reach, width + 2 * reach), np.nan, np.float32)
    padded[reach:-reach, reach:-reach] = np.where(edges.measured, far, np.nan)
    flat = padded.reshape(-1)
    row, column = np.divmod(pixels, width)
    at = (row + reach) * padded.shape[1] + column + reach
    own = flat[at]
    step = MIXED_SHARE * own
    between = np.zeros(len(pixels), dtype=bool)
    with np.errstate(invalid="ignore"):  # NaN, not measured, is neither nearer nor farther
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            for k in range(1, reach + 1):
                offset = k * (dr * padded.shape[1] + dc)
                before, after = flat[at - offset], flat[at + offset]
                between |= ((before < own - step) & (after > own + step)) | (
                    (after < own - step) & (before > own + step)
                )
    return between


def grown_over_edges(
    green: NDArray[np.bool_], edges: DepthEdges, reach_px: int = REGISTRATION_PX
) -> NDArray[np.bool_]:
    """(H, W) the green pixels (``green`` (H, W)) and the measured ones within ``reach_px``
    (:data:`REGISTRATION_PX`, :data:`MIXED_RIM_REACH_PX`) of them that continue their surface:
    within
    :data:`CONTINUOUS_SHARE` of the distance of the nearest green pixel there, and not behind
    a nearer surface (``edges``).

    A Kinect v2's colour image is registered to its depth through a calibration that leaves it
    a pixel or two off at the edges (and a JPEG's half-resolution chroma mixes two more pixels
    of the soil's colour into a leaf's edge), so a leaf's rim (and the whole of a tip a few
    pixels wide) takes the colour of the soil beside it and is not green. Those pixels are in front:
    nothing nearer lies beside them, and the leaf's green pixels next to them are at their
    distance. The soil beside a leaf that takes the leaf's green is behind the leaf, far
    beyond it: nothing is grown from it, and its points lie on the local ground, where the
    pass-through drops them (``filters.filter_station``)."""
    far = edges.far_m
    in_front = green & ~edges.behind  # the soil beside a leaf that took its green grows nothing
    nearest_green = cv2.erode(
        np.where(in_front, far, NOT_MEASURED_M).astype(np.float32), _square(reach_px)
    )
    continues = np.abs(far - nearest_green) <= CONTINUOUS_SHARE * far
    grown: NDArray[np.bool_] = green | (edges.measured & ~edges.behind & continues)
    return grown


def grown_into_weak_green(
    green: NDArray[np.bool_], weak: NDArray[np.bool_], edges: DepthEdges
) -> NDArray[np.bool_]:
    """(H, W) ``green`` grown, pixel by pixel up to :data:`WEAK_REACH_PX`, into the weakly
    green pixels (``weak``) beside it that are not behind a nearer surface (``edges``):
    hysteresis, as an edge detector keeps a weak edge that continues a strong one.

    A colour image compressed with its chroma at half resolution (JPEG, and the Kinect v2's own
    colour stream) or blurred by its registration to the depth mixes a leaf's green with the
    soil's colour over its last few pixels: the rim, and the whole of a tip a few pixels wide,
    falls below the threshold though still greener than the soil. The soil beside a leaf
    is behind it and is not grown into; soil a little green that continues a stem's foot lies
    on the local ground, where the pass-through drops it."""
    allowed = (green | (weak & ~edges.behind)).astype(np.uint8)
    grown = green.astype(np.uint8)
    for _ in range(WEAK_REACH_PX):
        grown = cv2.dilate(grown, _NEIGHBOURS) & allowed
    return grown.astype(bool)


def grown_into_uncoloured(
    green: NDArray[np.bool_], uncoloured: NDArray[np.bool_], edges: DepthEdges
) -> NDArray[np.bool_]:
    """(H, W) ``green`` grown, pixel by pixel up to :data:`UNCOLOURED_REACH_PX`, into the
    measured pixels without colour (``uncoloured``) that continue the surface of a pixel
    already grown beside them (within :data:`CONTINUOUS_SHARE` of its distance, ``edges``).

    libfreenect2 registers a Kinect v2's colour to its depth and writes black where the colour
    camera does not see the depth pixel: behind a nearer surface from where it stands, 5.2 cm
    beside the depth camera, and outside its view. On a tall plant near the camera a stretch of
    a lower leaf, seen by the depth camera, is hidden from the colour camera by the leaf above;
    read as not green, it was lost (a touching plot's tallest plant 2.5 cm low). The leaf's
    surface goes on from its green part into the black: grown along it. The black soil beside
    a leaf lies far behind the leaf's edge and is not grown into; soil that continues a stem's
    foot lies on the local ground, where the pass-through drops it. Grown step by step
    (:func:`_walked`): every frame libfreenect2 registers has black rows, and an erosion and a
    dilation of the whole frame at every step took 0.6-0.7 s of CPU on a 72-frame session."""
    return _walked(green, uncoloured, edges.far_m, UNCOLOURED_REACH_PX, CONTINUOUS_SHARE)


def _walked(
    green: NDArray[np.bool_],
    open_: NDArray[np.bool_],
    far_m: NDArray[np.float32],
    reach_px: int,
    share: float,
    accept: Callable[[NDArray[np.intp]], NDArray[np.bool_]] | None = None,
) -> NDArray[np.bool_]:
    """(H, W) ``green`` grown, pixel by pixel up to ``reach_px``, into the ``open_`` pixels
    that continue the surface of one already grown beside them: within ``share`` of their
    distance (``far_m``) of the nearest or the farthest grown neighbour; and, with ``accept``
    (flat pixel indices (P,) to (P,) whether each may be grown), only those it accepts (one it
    refuses is not judged again).

    Each step judges only the open pixels beside one grown at the step before (a few
    thousand at most of a frame's 217 088), against the nearest and the farthest of their
    grown neighbours: the same pixels as an erosion and a dilation of the whole frame at every
    step, which took 8-10 ms a frame, 1.4-5 ms with black pixels to grow into."""
    # on a one-pixel frame of pixels neither grown nor open, a neighbour is one constant step
    # away in the flat image wherever a pixel is
    far = np.pad(far_m, 1, constant_values=NOT_MEASURED_M).reshape(-1)
    grown = np.pad(green, 1).reshape(-1)
    open_ = np.pad(open_, 1).reshape(-1)
    padded = (green.shape[0] + 2, green.shape[1] + 2)
    steps = np.array([dr * padded[1] + dc for dr, dc in _EIGHT])
    beside = cv2.dilate(grown.reshape(padded).view(np.uint8), _NEIGHBOURS).view(bool)
    frontier = np.flatnonzero(open_ & beside.reshape(-1) & ~grown)
    for _ in range(reach_px):
        if len(frontier) == 0:
            break
        own = far[frontier]
        around = frontier[:, None] + steps  # (F, 8); each has a grown neighbour
        grown_there, depths = grown[around], far[around]
        nearest = np.where(grown_there, depths, NOT_MEASURED_M).min(axis=1)
        farthest = np.where(grown_there, depths, 0.0).max(axis=1)
        tolerance = share * own
        continues = (np.abs(own - nearest) <= tolerance) | (np.abs(own - farthest) <= tolerance)
        added = frontier[continues]
        if accept is not None and len(added):
            row, column = np.divmod(added, padded[1])
            accepted = accept((row - 1) * green.shape[1] + column - 1)
            open_[added[~accepted]] = False  # refused for good
            added = added[accepted]
        if len(added) == 0:
            break
        grown[added] = True
        # only a pixel beside one just grown has a new grown neighbour to be judged against
        near = (added[:, None] + steps).reshape(-1)
        near = np.sort(near[open_[near] & ~grown[near]])
        frontier = near[np.r_[True, near[1:] != near[:-1]]] if len(near) else near
    return grown.reshape(padded)[1:-1, 1:-1].copy()


_EIGHT = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
"""The eight neighbours of a pixel, as (row, column) steps."""


def frame_ground_heights(
    rays: NDArray[np.float64], depth_m: NDArray[np.float32], soil: NDArray[np.intp]
) -> Callable[[NDArray[np.intp]], NDArray[np.float64]] | None:
    """The height of pixels above the frame's ground: a plane fitted (least squares, twice
    refitted to the points within 5 cm or 2.5 times the median residual of it) through the
    ``soil`` sample pixels (S,) of the frame (depth ``depth_m`` (H, W), camera ``rays`` (H, W,
    3); every n-th, n the whole number of times :data:`GROUND_SAMPLE` goes into them),
    oriented with the camera above it. Returns the function of flat pixel indices (P,) to
    their heights (P,) in metres, or None with fewer than :data:`MIN_GROUND_PIXELS`."""
    ray = rays.reshape(-1, 3)
    depth = depth_m.reshape(-1)
    soil = soil[:: max(len(soil) // GROUND_SAMPLE, 1)]
    points = np.take(ray, soil, axis=0) * depth[soil, None].astype(np.float64)
    points = points[np.isfinite(points).all(axis=1)]
    if len(points) < MIN_GROUND_PIXELS:
        return None
    for _ in range(3):
        normal, offset = least_squares_plane(points)
        residual = np.abs(points @ normal + offset)
        near = residual <= max(0.05, 2.5 * float(np.median(residual)))
        if near.sum() < MIN_GROUND_PIXELS:
            break
        points = points[near]
    if offset < 0.0:  # the camera, at 0, above it
        normal, offset = -normal, -offset

    def heights(pixels: NDArray[np.intp]) -> NDArray[np.float64]:
        at = np.take(ray, pixels, axis=0) * depth[pixels, None].astype(np.float64)
        return at @ normal + offset

    return heights


def continued_surfaces(
    green: NDArray[np.bool_],
    edges: DepthEdges,
    heights: Callable[[NDArray[np.intp]], NDArray[np.float64]],
    colors: NDArray[np.uint8],
) -> NDArray[np.intp]:
    """The flat indices (ascending) of the measured pixels not in ``green`` (H, W) that
    continue a green pixel's surface, followed pixel by pixel up to
    :data:`CONTINUED_REACH_PX`: not behind a nearer surface (``edges``), within
    :data:`CONTINUED_SHARE` of the distance of the nearest or farthest pixel already reached
    beside them, :data:`CONTINUED_MIN_HEIGHT_M` above the frame's ground (``heights``,
    :func:`frame_ground_heights`), and of a colour with a hue (``colors`` (H * W, 3), the
    frame's: :func:`~fieldapp.recon.exg.hued`; a white or grey sphere or stake a leaf touches
    is not a leaf, nor is a pixel the colour camera did not see, which
    :func:`grown_into_uncoloured` judges).

    What colour did not call green at a plant's extremity: the last centimetres of a leaf's
    tip, a pixel or two wide at 2 m, whose colour mixes the leaf's with the soil behind it,
    and tips that yellow or dry. An independent renderer's touching plots lost 1.5-5 cm of
    their plants' widths so, there where the same sessions read without colour kept them."""
    open_ = edges.measured & ~edges.behind & ~green
    reached = _walked(
        green,
        open_,
        edges.far_m,
        CONTINUED_REACH_PX,
        CONTINUED_SHARE,
        lambda pixels: (
            (heights(pixels) > CONTINUED_MIN_HEIGHT_M) & hued(np.take(colors, pixels, axis=0))
        ),
    )
    return np.flatnonzero(reached & ~green)


def _read_frame(session: Session, station: int, capture: Capture) -> ReadFrame | str:
    """A capture's measured pixels, or the warning saying why it was skipped."""
    try:
        return frame_of(read_scan_capture(session, capture))
    except FormatError as error:
        return _skipped(station, capture, error)


def _green_keys(
    threshold: float, weak: float, tally: NDArray[np.int64] | None
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(EXG_KEYS + 1,) which colour keys are green and which weakly green: above the station's
    threshold (``weak``) and, for green with its ``tally``, above its soil's noise at their
    brightness (:func:`~fieldapp.recon.exg.noise_floors`). Weak green is held to the
    threshold alone: it grows only from green, along a surface (a floor there took the
    mixed pixels of leaf tips in shade)."""
    exg = exg_of_keys()
    weakly = np.append(exg > weak, False)
    if tally is None or not np.isfinite(threshold):
        return np.append(exg > threshold, False), weakly
    return thresholds_by_key(threshold, noise_floors(tally, threshold, NOISE_SIGMAS)), weakly


def _separation(
    frames: list[ReadFrame], exg_threshold: float | Literal["otsu"]
) -> tuple[Separation, float, float, int, NDArray[np.int64] | None, float | None]:
    """How the station's plants are told from its soil, the ExG threshold, the weaker one a
    pixel next to green needs (:data:`WEAK_SHARE` of the way from the soil's mean ExG to the
    threshold; both infinite by geometry) and how far the leaves' rims are grown
    (:data:`MIXED_RIM_REACH_PX` where mixed pixels fill the valley, else
    :data:`REGISTRATION_PX`), judged on every measured pixel of the station: from their tally
    by colour key, the same threshold as of the pixels' values one by one, at a fraction of
    the cost. Also the station's tally (for the noise floors) and, where Otsu's cut fell
    inside the soil and was moved (:func:`~fieldapp.recon.exg.above_the_soil`), that cut."""
    tallies = [frame.tally for frame in frames if frame.tally is not None]
    if len(tallies) < len(frames):
        return choose_separation(None), np.inf, np.inf, REGISTRATION_PX, None, None
    station_tally = tallies[0].copy()
    for tally in tallies[1:]:
        station_tally += tally  # in place: np.sum over the list is 200 times slower
    values, weights = exg_values(station_tally)
    if len(values) == 0:  # every pixel black: a colour stream that gave nothing
        return choose_separation(None), np.inf, np.inf, REGISTRATION_PX, None, None
    cut = otsu_threshold(values, weights)
    otsu = above_the_soil(values, weights, cut)
    separation = choose_separation(values, weights, otsu)
    rim_px = REGISTRATION_PX
    if exg_threshold == "otsu":
        threshold = mixed_pixel_threshold(values, weights, otsu)
        if threshold < otsu:  # the valley filled with mixed pixels: JPEG's colour
            rim_px = MIXED_RIM_REACH_PX
    else:
        threshold = float(exg_threshold)
    separation = keep_soil(separation, values, threshold, weights)
    if separation.by_geometry:
        return separation, np.inf, np.inf, rim_px, None, None
    soil = values <= threshold
    soil_mean = float(np.average(values[soil], weights=weights[soil])) if soil.any() else threshold
    weak = soil_mean + WEAK_SHARE * (threshold - soil_mean)
    moved = cut if otsu != cut and exg_threshold == "otsu" else None
    return separation, threshold, weak, rim_px, station_tally, moved


def _green_and_soil(
    frame: ReadFrame,
    separation: Separation,
    green_keys: tuple[NDArray[np.bool_], NDArray[np.bool_]],
    rim_px: int,
    grid: NDArray[np.intp],
    rays: NDArray[np.float64],
    crop: CropSettings,
) -> tuple[Cloud, Cloud, Cloud, Cloud, Cloud]:
    """One frame's green points (``green_keys``: (EXG_KEYS + 1,) which colour keys are green,
    and which weakly green, ``NO_KEY`` neither; grown into the weak green next to the green,
    :func:`grown_into_weak_green`, and over the leaves' rims, :func:`grown_over_edges`) and
    its soil sample
    (the measured ``grid`` pixels (M,) not green), in its camera frame, then both again at
    their blocks' median depths (:func:`block_median_depths`, for the registration); by geometry
    every measured point is "green" and the soil the whole grid, their medians plain (not held
    to a plant's surface: which points are plants is not known yet) and the same pixels in
    the raw and the median clouds. Last, with colour, the points of the surfaces continued
    from the green into pixels not green (:func:`continued_surfaces`; empty by geometry):
    they take no part in the registration, the outlier filters or the search for plants,
    and join the plant they continue after it is found (``filters.filter_station``,
    ``stages.fuse``), so what colour called green is read as without them."""
    if frame.measured.shape != rays.shape[:2]:
        raise ValueError(f"depth {frame.measured.shape} does not match the camera {rays.shape[:2]}")
    mixed = None
    continued, continued_mixed = np.zeros(0, dtype=np.intp), np.zeros(0, dtype=bool)
    if separation.by_geometry or frame.keys is None:
        measured = frame.measured.reshape(-1)
        green, soil = np.flatnonzero(measured), grid[measured[grid]]
        if separation.by_geometry:
            # without colour every pixel is one without colour of its own: those between two
            # surfaces hold a plant together but do not set its width, as in the colour's
            # black (RECONSTRUCTION.md, "Mixed pixels without colour")
            mixed = mixed_pixels(DepthEdges.of(frame.images.depth_m, frame.measured), green)
    else:
        shape = frame.measured.shape
        strong, weak = (np.take(key, frame.keys).reshape(shape) for key in green_keys)  # 2 x
        edges = DepthEdges.of(frame.images.depth_m, frame.measured)
        grown = grown_into_weak_green(strong, weak, edges)
        uncoloured = None
        if frame.uncoloured:
            uncoloured = np.take(uncoloured_keys(), frame.keys).reshape(shape)
            grown = grown_into_uncoloured(grown, uncoloured, edges)
        mask = grown_over_edges(grown, edges, rim_px).reshape(-1)
        green = np.flatnonzero(mask)
        soil = grid[(frame.keys[grid] != NO_KEY) & ~mask[grid]]
        heights = frame_ground_heights(rays, frame.images.depth_m, soil)
        if heights is not None:
            colors = frame.images.color.reshape(-1, 3)
            continued = continued_surfaces(mask.reshape(shape), edges, heights, colors)
            continued_mixed = mixed_pixels(edges, continued)
        # the pixels taken as plant without being green by their own colour (grown over a
        # leaf's rim, into weak green or into black; black with a trace of green counts as
        # black) that lie between two surfaces: kept (they hold a plant together), but they do
        # not set its width (RECONSTRUCTION.md, "Veils several pixels deep")
        borrowed = ~strong.reshape(-1)[green]
        if uncoloured is not None:
            borrowed |= uncoloured.reshape(-1)[green]
        looked_at = np.flatnonzero(borrowed)
        mixed = np.zeros(len(green), dtype=bool)
        mixed[looked_at] = mixed_pixels(edges, green[looked_at])

    depth = frame.images.depth_m
    green_m, soil_m = depth.reshape(-1)[green], depth.reshape(-1)[soil]
    green_rgb, soil_rgb, continued_rgb = (
        np.take(frame.images.color.reshape(-1, 3), p, axis=0) for p in (green, soil, continued)
    )

    def cloud(
        pixels: NDArray[np.intp],
        depth_m: NDArray[np.float32],
        rgb: NDArray[np.uint8],
        flags: NDArray[np.bool_] | None = None,
    ) -> Cloud:
        return backproject_pixels(
            pixels, depth_m, rgb, rays, crop.radius_m, crop.min_depth_m, flags
        )

    if separation.by_geometry:
        # every point's height above its local ground tells plant from soil; read at its
        # block's median depth, or in the sun the soil's noise stands clear of the ground and
        # joins the plants (RECONSTRUCTION.md, "Sunlight"). The same pixels in both clouds
        # (each kept where both depths are inside the crop), so the split of the median
        # points is the split of the points themselves.
        medians = np.full(depth.size, np.nan, dtype=np.float32)
        medians[green] = block_median_depths(depth, green)
        (green_cloud, green_steady), (soil_cloud, soil_steady) = (
            backproject_pixels_twice(
                pixels, own, medians[pixels], rgb, rays, crop.radius_m, crop.min_depth_m, flags
            )
            for pixels, own, rgb, flags in (
                (green, green_m, green_rgb, mixed),
                (soil, soil_m, soil_rgb, None),
            )
        )
        return green_cloud, soil_cloud, green_steady, soil_steady, Cloud.empty()
    soil_median = block_median_depths(depth, soil)
    noise = noise_per_m2(soil_m, soil_median)
    green_median = block_median_depths(depth, green, SAME_SURFACE_SIGMAS * noise)
    # the green point for point at its own depth and its block's: the pass-through takes
    # both (filters.filter_station), or in the sun green soil stood clear of its ground
    green_cloud, green_steady = backproject_pixels_twice(
        green, green_m, green_median, green_rgb, rays, crop.radius_m, crop.min_depth_m, mixed
    )
    return (
        green_cloud,
        cloud(soil, soil_m, soil_rgb),
        green_steady,
        cloud(soil, soil_median, soil_rgb),
        cloud(continued, depth.reshape(-1)[continued], continued_rgb, continued_mixed),
    )


def noise_per_m2(own_m: NDArray[np.float32], median_m: NDArray[np.float32]) -> float:
    """A frame's depth noise (standard deviation) per square metre of depth, from how far its
    soil sample's pixels (``own_m`` (M,)) moved to their blocks' medians (``median_m``;
    those that kept their own depth left out): robust (1.4826 x the median distance), and at
    least :data:`MIN_NOISE_PER_M2`. A time-of-flight pixel's noise grows about as its distance
    squared (the light it gets back falls so), in the shade and in the sun alike."""
    moved = median_m != own_m
    if not moved.any():
        return MIN_NOISE_PER_M2
    distance = np.abs(median_m[moved] - own_m[moved]) / own_m[moved] ** 2
    return max(float(1.4826 * np.median(distance)), MIN_NOISE_PER_M2)


def block_median_depths(
    depth_m: NDArray[np.float32],
    pixels: NDArray[np.intp],
    reach_per_m2: float | None = None,
    window_px: int = BLOCK_PX,
) -> NDArray[np.float32]:
    """(M,) the depth each of ``pixels`` ((M,) flat indices of measured pixels of ``depth_m``
    (H, W), NaN unmeasured) is given for the registration: the median of the measured depths
    in the ``window_px`` square around it where that median continues the pixel's own surface
    (within :data:`CONTINUOUS_SHARE` of its depth), its own depth elsewhere (beside an edge,
    where most of the window is another surface, and at the image's border, where the window
    is not centred). With ``reach_per_m2``, only the window's depths within that times the
    pixel's depth squared of its own are taken: a leaf over another a centimetre behind it is
    two surfaces, which a median of both would blur into one between them.

    Each soil sample point stands for the block of pixels around it, and the registration
    fits the overlaps' surfaces through these points: its own depth carries the whole of a
    pixel's noise, the block's median a quarter of it (the median of 25 values spreads 1.25 /
    5 as much as one). In the shade it hardly matters (1.5-2 mm at
    1-2 m); in sunlight, where a time-of-flight pixel's noise grows with the ambient light (3
    to 4 times the shade's, more at the far end of the views, where the stations overlap),
    the noise of the overlaps' soil biased the registration: a plot came out up to a
    centimetre shrunk and raised (RECONSTRUCTION.md, "Sunlight"). On a plane the median of a
    centred window is the centre pixel's depth exactly (1 / depth is affine in the pixel, so
    the window's depths pair off about the centre's), so the median moves nothing but the
    noise."""
    half = window_px // 2
    height, width = depth_m.shape
    own = depth_m.reshape(-1)[pixels]
    reach = None if reach_per_m2 is None else np.float32(reach_per_m2) * own * own
    median = np.empty(len(pixels), dtype=np.float32)
    slow = np.ones(len(pixels), dtype=bool)
    if reach is None and window_px in (3, 5) and len(pixels):  # cv2.medianBlur's float32 sizes
        # held to a surface, most windows of a leaf (and of noisy soil) reach past it, and
        # the whole image's filters cost more than sorting the few that do not
        whole, window_median = _whole_windows(depth_m, window_px)
        slow = ~whole.reshape(-1)[pixels]  # a window with a hole or past the border
        median[~slow] = window_median.reshape(-1)[pixels[~slow]]
    if slow.any():
        median[slow] = _sorted_window_medians(
            depth_m, pixels[slow], own[slow], None if reach is None else reach[slow], window_px
        )
    rows, columns = np.divmod(pixels, width)
    inside = (rows >= half) & (rows < height - half) & (columns >= half) & (columns < width - half)
    continuous = inside & (np.abs(median - own) <= np.float32(CONTINUOUS_SHARE) * own)
    return np.where(continuous, median, own).astype(np.float32)


def _whole_windows(
    depth_m: NDArray[np.float32], window_px: int
) -> tuple[NDArray[np.bool_], NDArray[np.float32]]:
    """Over the whole image: where a pixel's ``window_px`` square is measured throughout and
    inside the image, and there the window's median (``cv2.medianBlur``, exact: the 13th of 25
    values), what :func:`_sorted_window_medians` gives such a window, for a quarter of its
    cost on every pixel of a frame (8 against 36 ms)."""
    measured = np.isfinite(depth_m)
    filled = np.where(measured, depth_m, np.float32(0.0)).astype(np.float32)
    kernel = np.ones((window_px, window_px), dtype=np.uint8)
    whole = cv2.erode(
        measured.view(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0
    ).astype(bool)
    return whole, cv2.medianBlur(filled, window_px)


def _sorted_window_medians(
    depth_m: NDArray[np.float32],
    pixels: NDArray[np.intp],
    own: NDArray[np.float32],
    reach: NDArray[np.float32] | None,
    window_px: int,
) -> NDArray[np.float32]:
    """(M,) the median of the measured depths in each of ``pixels``' ``window_px`` square,
    only those within ``reach`` (M,) of the pixel's ``own`` depth when given."""
    half = window_px // 2
    width = depth_m.shape[1]
    padded = np.pad(depth_m, half, constant_values=np.nan)
    rows, columns = np.divmod(pixels, width)
    windows = np.lib.stride_tricks.sliding_window_view(padded, (window_px, window_px))
    window = windows[rows, columns].reshape(len(pixels), window_px * window_px)
    if reach is not None:
        window[np.abs(window - own[:, None]) > reach[:, None]] = np.nan
    window.sort(axis=1)  # NaN last
    count = np.count_nonzero(np.isfinite(window), axis=1)
    index = np.arange(len(pixels))
    median: NDArray[np.float32] = (window[index, (count - 1) // 2] + window[index, count // 2]) / 2
    return median
