"""Plain numpy for the preview (no Qt): the 3D point under a pixel (or the nearest measured
one), the distance between two picked points, the depth histogram and its percentile range,
the frame's cloud for the 3D view, IR scaled for display, and saving the current frame.

Camera frame: OpenCV (x right, y down, z forward), metres.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import Frame, Intrinsics

DEPTH_SCALE = 1000.0
"""Depth PNG units per metre (millimetres), as in session folders."""


@dataclass(frozen=True)
class PixelReading:
    """What lies under pixel (``u``, ``v``): its depth and 3D point (camera frame, metres),
    ``None`` where the depth is missing."""

    u: int
    v: int
    depth_m: float | None
    point_m: tuple[float, float, float] | None


def read_pixel(
    depth_m: NDArray[np.float32], intrinsics: Intrinsics, u: int, v: int
) -> PixelReading | None:
    """The reading at column ``u``, row ``v``; ``None`` outside the image."""
    height, width = depth_m.shape
    if not (0 <= u < width and 0 <= v < height):
        return None
    z = float(depth_m[v, u])
    if not np.isfinite(z):
        return PixelReading(u, v, None, None)
    x = (u - intrinsics.cx) / intrinsics.fx * z
    y = (v - intrinsics.cy) / intrinsics.fy * z
    return PixelReading(u, v, z, (x, y, z))


def pick_point(
    depth_m: NDArray[np.float32], intrinsics: Intrinsics, u: int, v: int, radius: int = 3
) -> PixelReading | None:
    """The measured pixel nearest (``u``, ``v``) within ``radius`` pixels (a click on a
    one-pixel hole still picks the surface around it); ``None`` outside the image or when
    nothing within ``radius`` has a depth."""
    height, width = depth_m.shape
    if not (0 <= u < width and 0 <= v < height):
        return None
    rows = slice(max(v - radius, 0), min(v + radius + 1, height))
    cols = slice(max(u - radius, 0), min(u + radius + 1, width))
    window = depth_m[rows, cols]
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(window) & (window > 0)
    if not valid.any():
        return None
    dv, du = np.nonzero(valid)
    nearest = int(np.argmin((dv + rows.start - v) ** 2 + (du + cols.start - u) ** 2))
    return read_pixel(
        depth_m, intrinsics, int(du[nearest]) + cols.start, int(dv[nearest]) + rows.start
    )


def distance_m(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    """Straight-line distance between two 3D points (metres)."""
    return float(np.linalg.norm(np.subtract(a, b)))


def valid_depths_m(depth_m: NDArray[np.float32], step: int = 2) -> NDArray[np.float32]:
    """Every ``step``-th row and column's measured depths, flat (a sample is enough for the
    histogram and the range)."""
    sample = depth_m[::step, ::step]
    with np.errstate(invalid="ignore"):
        kept: NDArray[np.float32] = sample[np.isfinite(sample) & (sample > 0)]
    return kept


def auto_levels_m(
    depths_m: NDArray[np.float32],
    percentiles: tuple[float, float] = (2.0, 98.0),
    min_span_m: float = 0.05,
) -> tuple[float, float] | None:
    """The colour range that follows the scene: the depths' ``percentiles`` (a stray far or
    near pixel does not stretch it), at least ``min_span_m`` wide; ``None`` with no depth."""
    if depths_m.size == 0:
        return None
    low, high = (float(x) for x in np.percentile(depths_m, percentiles))
    middle = (low + high) / 2
    if high - low < min_span_m:
        low, high = middle - min_span_m / 2, middle + min_span_m / 2
    return max(low, 0.0), high


def depth_histogram(
    depths_m: NDArray[np.float32], range_m: tuple[float, float] = (0.0, 8.0), bins: int = 160
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(bin edges (bins + 1,) metres, counts (bins,)) of ``depths_m`` over ``range_m``."""
    counts, edges = np.histogram(depths_m, bins=bins, range=range_m)
    return edges, counts


def best_arrangement(
    area: tuple[float, float], image: tuple[float, float], count: int
) -> tuple[str, float]:
    """Side by side (``"row"``) or one above the other (``"column"``): whichever shows
    ``count`` images of size ``image`` (w, h) larger in ``area`` (w, h); with the scale."""
    (area_w, area_h), (image_w, image_h) = area, image
    row = min(area_w / (count * image_w), area_h / image_h)
    column = min(area_w / image_w, area_h / (count * image_h))
    return ("row", row) if row >= column else ("column", column)


def cloud_points(
    frame: Frame, intrinsics: Intrinsics, step: int = 4, max_range_m: float = 4.5
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Every ``step``-th pixel's point with valid depth up to ``max_range_m``.

    Returns (points (N, 3) float32 in a viewing frame: x right, y forward, z up, i.e. the
    camera's (x, z, -y)), colours (N, 4) float32 RGBA in 0..1)."""
    depth = frame.depth_m[::step, ::step]
    v, u = np.mgrid[0 : frame.depth_m.shape[0] : step, 0 : frame.depth_m.shape[1] : step]
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(depth) & (depth > 0) & (depth <= max_range_m)
    z = depth[keep]
    x = (u[keep] - intrinsics.cx) / intrinsics.fx * z
    y = (v[keep] - intrinsics.cy) / intrinsics.fy * z
    points = np.stack([x, z, -y], axis=1).astype(np.float32)
    rgb = frame.color[::step, ::step][keep].astype(np.float32) / 255.0
    colours = np.concatenate([rgb, np.ones((len(rgb), 1), np.float32)], axis=1)
    return points, colours


def depth_indices(depth_m: NDArray[np.float32], low_m: float, high_m: float) -> NDArray[np.uint8]:
    """(H, W) uint8 indices into a 256-entry lookup table: 0 where depth is missing, 1..255
    from ``low_m`` to ``high_m`` (clipped). Cheaper on the GUI thread than letting the image
    item scale float data."""
    scale = np.float32(254.0 / max(high_m - low_m, 1e-6))
    with np.errstate(invalid="ignore"):
        scaled = (depth_m - np.float32(low_m)) * scale
        np.clip(scaled, 0.0, 254.0, out=scaled)
    indices = np.zeros(depth_m.shape, np.uint8)
    valid = np.isfinite(scaled)
    indices[valid] = scaled[valid].astype(np.uint8) + 1
    return indices


def depth_lut(colours: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """(256, 4) RGBA table for :func:`depth_indices`: black for missing, then ``colours``
    ((255, 3 or 4) uint8, low to high)."""
    lut = np.zeros((256, 4), np.uint8)
    lut[0] = (0, 0, 0, 255)
    lut[1:, : colours.shape[1]] = colours
    lut[1:, 3] = 255
    return lut


def ir_for_display(
    ir: NDArray[np.uint16], low_pct: float = 1.0, high_pct: float = 99.0
) -> NDArray[np.uint8]:
    """(H, W) uint8: IR amplitude stretched between its percentiles (the raw range is wide)."""
    low, high = np.percentile(ir[::4, ::4], [low_pct, high_pct])  # a sample is enough
    span = max(float(high - low), 1.0)
    scaled = np.clip((ir.astype(np.float32) - float(low)) / span, 0.0, 1.0)
    shown: NDArray[np.uint8] = (scaled * 255.0).astype(np.uint8)
    return shown


def save_frame(
    folder: Path, frame: Frame, intrinsics: Intrinsics, stem: str | None = None
) -> list[Path]:
    """Write ``frame`` into ``folder``: 16-bit depth PNG (mm), colour PNG, IR PNG (when
    present) and a JSON of the intrinsics and frame metadata. Returns the paths written."""
    from fieldapp.io.durable import write_bytes_durably
    from fieldapp.io.images import depth_m_to_units, encode_png

    stem = stem or time.strftime("frame-%Y%m%d-%H%M%S")
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    images: list[tuple[str, NDArray[np.generic], bool]] = [
        ("depth", depth_m_to_units(frame.depth_m, DEPTH_SCALE), False),
        ("color", frame.color, True),
    ]
    if frame.ir is not None:
        images.append(("ir", frame.ir, False))
    for kind, image, rgb in images:
        path = folder / f"{stem}-{kind}.png"
        write_bytes_durably(path, encode_png(image, rgb=rgb))
        written.append(path)
    about = {
        "depth_scale": DEPTH_SCALE,
        "intrinsics": {
            "width": intrinsics.width, "height": intrinsics.height,
            "fx": intrinsics.fx, "fy": intrinsics.fy, "cx": intrinsics.cx, "cy": intrinsics.cy,
        },
        "timestamp_s": frame.timestamp_s,
        "meta": {k: v for k, v in frame.meta.items() if isinstance(v, int | float | str)},
    }  # fmt: skip
    meta_path = folder / f"{stem}.json"
    write_bytes_durably(meta_path, (json.dumps(about, indent=2) + "\n").encode("utf-8"))
    written.append(meta_path)
    return written
