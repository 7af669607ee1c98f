"""Re-noising: fresh Kinect v2 sensor noise on a noise-free render, fast enough for 30 fps.

Ray casting one simulated frame takes longer than a Kinect frame period on a small machine
(see ``benchmarks/bench_camera.py``), so the simulated camera renders the scene once per rig
pose without noise (:func:`prepare`, slow) and draws every frame's noise on it
(:func:`renoise`, a few milliseconds). The noise follows the simulator's sensor model
(:class:`devices.sim.render.SensorModel`, ``shared/KINECT-V2.md``): axial noise by distance
and incidence (Fankhauser et al. 2015), stronger on dim returns, mixed pixels along depth
edges, dropouts at grazing angles and where too little IR returns, 0.5-4.5 m range. The
incidence angle is the renderer's own (``Frame.meta["cos_incidence"]``); for other clean
frames it is estimated from normals of the depth image (exact on smooth surfaces, poor on thin
leaves).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import Frame, Intrinsics
from devices.sim.render import (
    COS_INCIDENCE,
    MAX_RANGE_M,
    MIN_RANGE_M,
    SensorModel,
    axial_noise_m,
    ray_table,
)

COLOUR_NOISE = 0.03
"""Relative noise of the linear colour per pixel (the renderer's), about 1/2.2 of it in sRGB."""


@dataclass
class CleanView:
    """One rig pose rendered without noise, with what the noise needs precomputed.

    ``depth_m`` (H, W) float32 NaN = missing for good; ``sigma_m`` (H, W) float32 axial noise;
    ``drop_index`` (K,) flat pixels that may drop with probability ``drop_p`` (K,);
    ``edges``: per neighbour direction, (flat pixel index (M,), the neighbour's depth (M,)).
    """

    depth_m: NDArray[np.float32]
    color: NDArray[np.uint8]
    ir: NDArray[np.float32]
    sigma_m: NDArray[np.float32]
    drop_index: NDArray[np.intp]
    drop_p: NDArray[np.float32]
    edges: list[tuple[NDArray[np.intp], NDArray[np.float32]]]
    meta: dict[str, object] = field(default_factory=dict)


def cos_incidence(depth_m: NDArray[np.float32], intrinsics: Intrinsics) -> NDArray[np.float32]:
    """(H, W) |cos| of the angle between each pixel's ray and the depth surface's normal;
    1 where the normal is undefined (missing neighbours, image border)."""
    rays = ray_table(intrinsics).reshape(intrinsics.height, intrinsics.width, 3)
    points = depth_m[..., None] * rays
    du = np.zeros_like(points)
    dv = np.zeros_like(points)
    du[:, 1:-1] = points[:, 2:] - points[:, :-2]
    dv[1:-1] = points[2:] - points[:-2]
    normal = np.cross(du, dv)
    dot = np.abs(np.einsum("hwc,hwc->hw", normal, rays))
    scale = np.linalg.norm(normal, axis=2) * np.linalg.norm(rays, axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = dot / scale
    return np.where(np.isfinite(cos) & (scale > 0), np.clip(cos, 0.0, 1.0), 1.0).astype(np.float32)


def _edges(
    depth_m: NDArray[np.float32], sensor: SensorModel
) -> list[tuple[NDArray[np.intp], NDArray[np.float32]]]:
    valid = np.isfinite(depth_m)
    width = depth_m.shape[1]
    edges = []
    for axis in (0, 1):
        for shift in (1, -1):
            other = np.roll(depth_m, shift, axis=axis)
            other_valid = np.roll(valid, shift, axis=axis)
            border = 0 if shift == 1 else -1  # np.roll wraps around: no edge across the border
            if axis == 0:
                other_valid[border, :] = False
            else:
                other_valid[:, border] = False
            with np.errstate(invalid="ignore"):
                edge = valid & other_valid & (np.abs(other - depth_m) > sensor.edge_jump * depth_m)
            rows, cols = np.nonzero(edge)
            index = rows * width + cols
            edges.append((index.astype(np.intp), other[rows, cols].astype(np.float32)))
    return edges


def prepare(clean: Frame, intrinsics: Intrinsics, sensor: SensorModel) -> CleanView:
    """Precompute the noise of a noise-free render (``SensorModel(noise=False)``)."""
    depth = clean.depth_m.astype(np.float32)
    ir = (clean.ir if clean.ir is not None else np.zeros(depth.shape)).astype(np.float32)
    valid = np.isfinite(depth)
    true_cos = clean.meta.get(COS_INCIDENCE)
    # the renderer's own incidence when it gives one; normals of the depth image are poor on
    # thin leaves, and too many dropouts there thin the plants
    cos = true_cos if isinstance(true_cos, np.ndarray) else cos_incidence(depth, intrinsics)
    theta = np.arccos(cos)
    weak = np.sqrt(np.clip(400.0 / np.maximum(ir, 1.0), 1.0, 9.0))  # dim returns are noisier
    sigma = np.where(valid, axial_noise_m(np.where(valid, depth, 1.0), theta) * weak, 0.0)
    span = sensor.grazing_end_deg - sensor.grazing_start_deg
    p_drop = np.clip((np.degrees(theta) - sensor.grazing_start_deg) / span, 0.0, 1.0)
    depth = np.where(valid & (ir >= sensor.min_ir), depth, np.nan).astype(np.float32)
    drop_index = np.flatnonzero(np.isfinite(depth) & (p_drop > 0))
    return CleanView(
        depth_m=depth,
        color=clean.color,
        ir=ir,
        sigma_m=sigma.astype(np.float32),
        drop_index=drop_index,
        drop_p=p_drop.ravel()[drop_index].astype(np.float32),
        edges=_edges(depth, sensor),
        meta={k: v for k, v in clean.meta.items() if k != COS_INCIDENCE},
    )


def renoise(view: CleanView, sensor: SensorModel, rng: np.random.Generator) -> Frame:
    """A frame of ``view`` with fresh noise; ``timestamp_s`` is left for the caller."""
    noise = rng.standard_normal(view.depth_m.shape, dtype=np.float32)
    depth = view.depth_m + view.sigma_m * noise
    flat = depth.reshape(-1)
    for index, other in view.edges:
        chosen = rng.random(len(index), dtype=np.float32) < sensor.flying_fraction / 4
        mix = rng.random(int(chosen.sum()), dtype=np.float32)
        here = flat[index[chosen]]
        flat[index[chosen]] = here + mix * (other[chosen] - here)
    dropped = rng.random(len(view.drop_index), dtype=np.float32) < view.drop_p
    flat[view.drop_index[dropped]] = np.nan
    with np.errstate(invalid="ignore"):
        depth[(depth < MIN_RANGE_M) | (depth > MAX_RANGE_M)] = np.nan
    ir_noise = 1.0 + sensor.ir_noise * rng.standard_normal(view.ir.shape, dtype=np.float32)
    gain = 1.0 + (COLOUR_NOISE / 2.2) * rng.standard_normal(view.depth_m.shape, dtype=np.float32)
    color = np.clip(view.color * gain[..., None] + 0.5, 0, 255).astype(np.uint8)
    return Frame(
        depth_m=depth,
        color=color,
        ir=np.clip(view.ir * ir_noise, 0, 65535).astype(np.uint16),
        meta=dict(view.meta),
    )
