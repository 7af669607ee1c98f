"""Quiet captures: one frame made of ``n`` consecutive frames by a per-pixel median.

The median keeps depth edges sharp (a mean would blur them into flying pixels) and divides
the axial noise by about sqrt(2 n / pi). A pixel missing in most of the frames stays missing,
so dropouts that flicker do not become invented depth.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import Frame

ReadFrame = Callable[[float], Frame]
"""Reads the next frame, waiting at most the given number of seconds."""


def median_depth_m(stack_m: NDArray[np.float32]) -> NDArray[np.float32]:
    """Per-pixel median of (n, H, W) depths ignoring NaN; NaN where fewer than half are valid.

    A pixel is kept when its valid count k satisfies 2 k >= n ("missing in most frames" means
    missing in more than half); its value is the median of its k valid samples.
    """
    n = stack_m.shape[0]
    ordered = np.sort(stack_m, axis=0)  # NaN sorts last
    valid = np.count_nonzero(np.isfinite(stack_m), axis=0)
    low = np.clip((valid - 1) // 2, 0, n - 1)[None]
    high = np.clip(valid // 2, 0, n - 1)[None]
    median = 0.5 * (
        np.take_along_axis(ordered, low, axis=0)[0] + np.take_along_axis(ordered, high, axis=0)[0]
    )
    median[(2 * valid < n) | (valid == 0)] = np.nan
    result: NDArray[np.float32] = median.astype(np.float32)
    return result


def combine_frames(frames: Sequence[Frame]) -> Frame:
    """One frame from several of the same camera: median depth, colour and IR.

    ``timestamp_s`` is the last frame's; ``meta`` is the last frame's plus ``frames_combined``
    and ``first_timestamp_s``.
    """
    if not frames:
        raise ValueError("combine_frames needs at least one frame")
    shapes = {f.depth_m.shape for f in frames}
    if len(shapes) != 1:
        raise ValueError(f"frames differ in size: {sorted(shapes)}")
    depth = median_depth_m(np.stack([f.depth_m for f in frames]).astype(np.float32))
    color = np.median(np.stack([f.color for f in frames]), axis=0)
    irs = [f.ir for f in frames if f.ir is not None]
    ir = np.median(np.stack(irs), axis=0) if len(irs) == len(frames) else None
    last = frames[-1]
    meta = {
        **last.meta,
        "frames_combined": len(frames),
        "first_timestamp_s": frames[0].timestamp_s,
    }
    return Frame(
        depth_m=depth,
        color=np.rint(color).astype(np.uint8),
        ir=None if ir is None else np.rint(ir).astype(np.uint16),
        timestamp_s=last.timestamp_s,
        meta=meta,
    )


def capture_median(read: ReadFrame, n: int, timeout_s: float) -> Frame:
    """Read ``n`` consecutive frames (each within ``timeout_s``) and combine them."""
    if n < 1:
        raise ValueError(f"capture needs n >= 1 frames, got {n}")
    return combine_frames([read(timeout_s) for _ in range(n)])
