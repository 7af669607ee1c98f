"""The Kinect v2 sensor model (``shared/KINECT-V2.md``): range, axial noise by distance and
incidence angle (Fankhauser et al. 2015), flying pixels on depth edges (single, or a veil several
pixels deep: ``veil_px``), dropouts at grazing angles and on surfaces too dark in IR, and the
sun's own infrared (``sun_ir``): shot noise that grows with the ambient light over the camera's
returned light, and no depth where the return drowns in it."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import Intrinsics

MIN_RANGE_M = 0.5
MAX_RANGE_M = 4.5


@dataclass(frozen=True)
class SensorModel:
    """Noise and artefacts. Set ``noise=False`` for exact depth (tests of geometry)."""

    noise: bool = True
    flying_fraction: float = 0.5
    """Share of depth-edge pixels that return a mixture of the two surfaces."""
    edge_jump: float = 0.04
    """Relative depth jump between neighbours that makes an edge."""
    veil_px: int = 0
    """How many pixels deep a veil of mixed pixels runs from a near surface's edge over the
    farther one beside it, stepping evenly from the one to the other (:func:`veiled`; 0: only
    the single flying pixels of ``flying_fraction``)."""
    grazing_start_deg: float = 75.0
    grazing_end_deg: float = 88.0
    """Dropout probability rises from 0 to 1 between these incidence angles."""
    min_ir: float = 60.0
    """IR amplitude below which there is no depth (too little returned light)."""
    ir_gain: float = 24000.0
    """IR amplitude of a white (albedo 1) surface facing the camera at 1 m."""
    ir_noise: float = 0.02
    sun_azimuth_deg: float = 135.0
    sun_elevation_deg: float = 50.0
    sky: float = 0.35
    color: bool = True
    """Shade the colour image (off for IR-only calibration images: faster)."""
    shadows: bool = True
    """Cast shadow rays towards the sun for the colour image."""
    supersample: int = 1
    """Rays per pixel side (IR and colour are averaged; 3 for calibration images)."""
    color_noise: float = 0.0
    """Standard deviation, in 8-bit levels, of each colour channel's own noise (0: the colour
    varies only in brightness, 3 % per pixel). A colour camera's channels are read apart: dark
    pixels change hue from one frame to the next (3-5 levels is common for a Kinect v2's colour
    stream in shade)."""
    depth_offset_m: float = 0.0
    """Added to every depth measured: a unit's static offset (``shared/KINECT-V2.md``: 1-4 cm
    is common after calibration)."""
    sun_ir: float = 0.0
    """Ambient infrared in the camera's band from a white surface facing the sun, in the units
    of ``ir`` amplitude (0: indoors or overcast dusk; ``FULL_SUN_IR``: clear midday sun)."""
    drowned_start: float = 40.0
    drowned_end: float = 120.0
    """No depth: probability rising from 0 to 1 as ambient over returned light goes between
    these (the sensor's own confidence test rejects a phase lost in shot noise)."""


FULL_SUN_IR = 80_000.0
"""``SensorModel.sun_ir`` of a clear midday sun: on sunlit soil 2 m away, ambient about 15 times
the returned light, depth noise about 4 times the shade's (``shared/KINECT-V2.md``: "noise that
rises in sunlight"); sunlit soil seen at grazing angles near the crop radius starts to drop out,
sunlit leaves stay measured but noisy."""


def axial_noise_m(
    depth_m: NDArray[np.floating], incidence_rad: NDArray[np.floating]
) -> NDArray[np.float64]:
    """Standard deviation (m) of Kinect v2 depth at ``depth_m`` and incidence angle (rad).

    sigma_z [mm] = 1.5 - 0.5 z + 0.3 z^2 + 0.1 z^1.5 theta^2 / (pi/2 - theta)^2.
    """
    z = np.asarray(depth_m, np.float64)
    theta = np.minimum(np.asarray(incidence_rad, np.float64), np.radians(89.0))
    sigma_mm = 1.5 - 0.5 * z + 0.3 * z**2 + 0.1 * z**1.5 * theta**2 / (np.pi / 2 - theta) ** 2
    return sigma_mm / 1000.0  # type: ignore[no-any-return]


def sensor_depth(
    sensor: SensorModel,
    depth: NDArray[np.float32],
    cos_incidence: NDArray[np.float32],
    ir: NDArray[np.float32],
    rng: np.random.Generator,
    ambient: NDArray[np.float32] | None = None,
) -> NDArray[np.float32]:
    """Noisy depth (H, W) float32 from exact ``depth`` (H, W, inf = nothing hit),
    ``cos_incidence``, ``ir`` amplitude and the ``ambient`` infrared on each pixel (H, W, the
    same units; none: the shade): axial noise, flying pixels, dropouts; NaN where missing.

    A time-of-flight pixel's phase noise goes as sqrt(returned + ambient) / returned, so the
    ambient multiplies the shade's noise by sqrt(1 + ambient / returned)."""
    valid = np.isfinite(depth)
    safe = np.where(valid, veiled(depth, sensor.veil_px, sensor.edge_jump), np.float32(1.0))
    theta = np.arccos(np.clip(cos_incidence, 0.0, 1.0))
    sigma = axial_noise_m(safe, theta).astype(np.float32)
    weak = np.sqrt(np.clip(400.0 / np.maximum(ir, 1.0), 1.0, 9.0))  # dim returns are noisier
    drowned = np.zeros(depth.shape, bool)
    if ambient is not None:
        share = ambient / np.maximum(ir, np.float32(1.0))
        weak = weak * np.sqrt(1.0 + share)
        p_drowned = (share - sensor.drowned_start) / (sensor.drowned_end - sensor.drowned_start)
        drowned = rng.random(depth.shape, np.float32) < p_drowned
    noisy = safe + sigma * weak * rng.standard_normal(depth.shape, np.float32)
    noisy = flying_pixels(noisy, valid, sensor, rng)
    span = np.radians(sensor.grazing_end_deg - sensor.grazing_start_deg)
    p_drop = (theta - np.radians(sensor.grazing_start_deg)) / span
    dropped = (rng.random(depth.shape, np.float32) < p_drop) | (ir < sensor.min_ir) | drowned
    noisy[~valid | dropped] = np.nan
    return noisy


def veiled(depth: NDArray[np.float32], veil_px: int, edge_jump: float) -> NDArray[np.float32]:
    """``depth`` (H, W; inf where nothing is hit) with a veil of mixed pixels beside every depth
    edge: a pixel ``k`` pixels (1..``veil_px``, the nearest such surface within a square's reach)
    from a surface nearer than it by more than ``edge_jump`` of its distance returns the depth
    ``k / (veil_px + 1)`` of the way from that surface to its own. A time-of-flight camera's
    optics and its depth pipeline's smoothing spread an edge's mixture over several pixels of the
    farther surface, a veil of points in the air along the rays past a leaf's edge (an
    independent renderer's veils ran up to four pixels deep)."""
    if veil_px <= 0:
        return depth
    hit = np.isfinite(depth)
    own = np.where(hit, depth, np.float32(np.inf)).astype(np.float32)
    out = own.copy()
    done = ~hit
    square = np.ones((3, 3), np.uint8)
    # the near side of every edge: a pixel with a neighbour farther by more than the jump (only
    # these spread a veil, not a surface sloping away a little at each pixel)
    farthest = cv2.dilate(np.where(hit, own, np.float32(0.0)), square)
    nearest = np.where(farthest > own * np.float32(1.0 + edge_jump), own, np.float32(np.inf))
    nearest = nearest.astype(np.float32)
    for k in range(1, veil_px + 1):
        nearest = cv2.erode(nearest, square, borderType=cv2.BORDER_REPLICATE)
        edge = ~done & (nearest < own * np.float32(1.0 - edge_jump))
        share = np.float32(k / (veil_px + 1))
        out[edge] = nearest[edge] + share * (own[edge] - nearest[edge])
        done |= edge
    return np.where(np.isfinite(depth), out, depth).astype(np.float32)


def flying_pixels(
    depth: NDArray[np.float32],
    valid: NDArray[np.bool_],
    sensor: SensorModel,
    rng: np.random.Generator,
) -> NDArray[np.float32]:
    """Mix the depths of both sides at a share of the pixels on depth edges (mixed pixels)."""
    out = depth.copy()
    jump = sensor.edge_jump * depth
    h, w = depth.shape
    for axis in (0, 1):
        # pixel i against its next neighbour i + 1 along the axis (no wrapping around)
        here = (slice(0, h - 1), slice(None)) if axis == 0 else (slice(None), slice(0, w - 1))
        ahead = (slice(1, h), slice(None)) if axis == 0 else (slice(None), slice(1, w))
        step = depth[ahead] - depth[here]
        edge = valid[here] & valid[ahead] & (np.abs(step) > jump[here])
        for side, sign in ((here, 1.0), (ahead, -1.0)):
            chosen = edge & (rng.random(edge.shape, np.float32) < sensor.flying_fraction / 4)
            mix = rng.random(edge.shape, np.float32)
            target = out[side]
            target[chosen] = (depth[side] + sign * mix * step)[chosen]
    return out


MAX_COLOR_SHIFT_PX = 3
"""The furthest a simulated colour image may be registered off its depth (pixels a side)."""


def misregistered(color: NDArray[np.uint8], dx_px: int, dy_px: int) -> NDArray[np.uint8]:
    """``color`` (H, W, 3) registered ``dx_px`` pixels right and ``dy_px`` down of where it
    belongs on the depth image, as a registration calibration a pixel or two off leaves a
    Kinect v2's colour (the rows and columns it uncovers repeat the image's edge)."""
    if max(abs(dx_px), abs(dy_px)) > MAX_COLOR_SHIFT_PX:
        raise ValueError(f"colour shift must be within {MAX_COLOR_SHIFT_PX} pixels a side")
    h, w = color.shape[:2]
    top, left = max(dy_px, 0), max(dx_px, 0)
    padded = np.pad(color, ((top, max(-dy_px, 0)), (left, max(-dx_px, 0)), (0, 0)), mode="edge")
    y0, x0 = max(-dy_px, 0), max(-dx_px, 0)
    return padded[y0 : y0 + h, x0 : x0 + w]


COLOR_CAMERA = (1081.37, 1081.37, 959.5, 539.5, 1920, 1080)
"""A Kinect v2's colour camera as libfreenect2 describes it by default: fx, fy, cx, cy
(pixels) and its width and height (about 84 x 53 degrees: less high than the depth camera's
60 degrees)."""
COLOR_BASELINE_M = 0.052
"""How far the colour camera stands beside the depth camera (libfreenect2's ``shift_m``)."""
OCCLUSION_WINDOW_PX = (2, 1)
"""Half the width and height (colour pixels) over which a depth pixel shadows others, and..."""
OCCLUSION_TOLERANCE = 0.01
"""...how much farther (a share of its depth) a depth pixel may be than the nearest one
mapped there and still be given its colour (libfreenect2's registration filter)."""


def registered_as_libfreenect2(
    color: NDArray[np.uint8], depth_m: NDArray[np.floating], camera: Intrinsics
) -> NDArray[np.uint8]:
    """``color`` (H, W, 3, registered exactly to ``depth_m`` of the depth ``camera``, pinhole)
    with what libfreenect2's registration (its filter on, the default) leaves no
    colour in black: depth pixels outside the colour camera's view (rows at the top and bottom:
    its field is less high) and those the colour camera, :data:`COLOR_BASELINE_M` beside the
    depth camera, sees behind a nearer surface (a band beside every near edge), and pixels
    without depth."""
    cfx, cfy, ccx, ccy, width, height = COLOR_CAMERA
    v, u = np.nonzero(depth_m > 0)
    z = depth_m[v, u].astype(np.float64)
    x_n, y_n = (u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy
    uc = np.rint(cfx * (x_n + COLOR_BASELINE_M / z) + ccx).astype(np.intp)
    vc = np.rint(cfy * y_n + ccy).astype(np.intp)
    inside = (uc >= 0) & (uc < width) & (vc >= 0) & (vc < height)
    v, u, z, uc, vc = v[inside], u[inside], z[inside], uc[inside], vc[inside]
    half_w, half_h = OCCLUSION_WINDOW_PX
    nearest = np.full((height + 2 * half_h, width + 2 * half_w), np.inf)
    for dy in range(-half_h, half_h + 1):
        for dx in range(-half_w, half_w + 1):
            np.minimum.at(nearest, (vc + half_h + dy, uc + half_w + dx), z)
    seen = (z - nearest[vc + half_h, uc + half_w]) / z <= OCCLUSION_TOLERANCE
    out = np.zeros_like(color)
    out[v[seen], u[seen]] = color[v[seen], u[seen]]
    return out
