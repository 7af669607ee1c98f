"""Ray casting a scene into Kinect v2 frames: depth with the sensor's noise, colour, IR.

One ray per pixel from a precomputed table (camera-frame directions with z = 1, so Open3D's
``t_hit`` is the depth along the optical axis), cast with Open3D's ``RaycastingScene``.
Sensor model (:mod:`devices.sim.sensor`, ``shared/KINECT-V2.md``): axial noise by distance
and incidence angle (Fankhauser et al. 2015), flying pixels along depth edges, dropouts at
grazing angles and on surfaces too dark in IR, no return outside 0.5-4.5 m. Colour: albedo lit
by the sun with cast shadows and sky light. IR: the camera's own illumination,
albedo x cos(incidence) / distance^2.
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import open3d as o3d
from numpy.typing import NDArray

from devices.camera.frames import Frame, Intrinsics
from devices.geometry import Matrix4
from devices.sim.linalg import rotate_t
from devices.sim.scene import Body, Scene
from devices.sim.sensor import (
    MAX_RANGE_M,
    MIN_RANGE_M,
    SensorModel,
    axial_noise_m,
    sensor_depth,
)
from devices.sim.shadows import ShadowMap

__all__ = [  # the sensor model is re-exported: callers import it from here
    "MAX_RANGE_M",
    "MIN_RANGE_M",
    "Renderer",
    "SensorModel",
    "axial_noise_m",
    "ray_table",
]


def tensor(array: NDArray[Any]) -> o3d.core.Tensor:
    """An Open3D tensor sharing a contiguous copy of ``array``."""
    return o3d.core.Tensor.from_numpy(np.ascontiguousarray(array))


def scene_raycaster(scene: Scene) -> o3d.t.geometry.RaycastingScene:
    """A raycasting scene of ``scene``'s bodies; geometry id = index in ``scene.bodies``."""
    raycaster = o3d.t.geometry.RaycastingScene()
    for body in scene.bodies:
        raycaster.add_triangles(
            tensor(body.vertices_m.astype(np.float32)), tensor(body.triangles.astype(np.uint32))
        )
    return raycaster


@functools.lru_cache(maxsize=4)
def ray_table(intrinsics: Intrinsics, supersample: int = 1) -> NDArray[np.float32]:
    """(H * W * s^2, 3) camera-frame ray directions with z = 1, pixel by pixel (row-major),
    ``s`` x ``s`` sub-rays per pixel; lens distortion undone by OpenCV when there is some."""
    s = supersample
    offsets = (np.arange(s) + 0.5) / s - 0.5
    v, u, dv, du = np.meshgrid(
        np.arange(intrinsics.height), np.arange(intrinsics.width), offsets, offsets, indexing="ij"
    )
    pixels = np.stack([(u + du).ravel(), (v + dv).ravel()], axis=1).astype(np.float64)
    if intrinsics.has_distortion:
        normalised = cv2.undistortPoints(
            pixels.reshape(-1, 1, 2), intrinsics.K, np.array(intrinsics.distortion)
        ).reshape(-1, 2)
    else:
        normalised = (pixels - [intrinsics.cx, intrinsics.cy]) / [intrinsics.fx, intrinsics.fy]
    table = np.column_stack([normalised, np.ones(len(normalised))]).astype(np.float32)
    table.flags.writeable = False  # shared between renderers
    return table


COS_INCIDENCE = "cos_incidence"
"""``Frame.meta`` key of the true (H, W) float32 |cos| of each pixel's incidence angle: what a
re-noiser needs to draw the sensor's noise on a noise-free render."""


@dataclass
class Hits:
    """What the rays hit, flattened, float32: ``t`` (N,) depth along the axis (inf = nothing),
    ``points`` (N, 3) field frame, ``normals`` (N, 3) facing the camera, ``cos_incidence`` (N,),
    ``range_m`` (N,) distance along the ray, ``rgb`` (N, 3) and ``ir`` (N,) albedo, ``body`` (N,)
    index of the body hit (meaningless where ``t`` is inf)."""

    t: NDArray[np.float32]
    points: NDArray[np.float32]
    normals: NDArray[np.float32]
    cos_incidence: NDArray[np.float32]
    range_m: NDArray[np.float32]
    rgb: NDArray[np.float32]
    ir: NDArray[np.float32]
    body: NDArray[np.int64]


class Renderer:
    """Renders a :class:`Scene` as seen by a camera of ``intrinsics`` at ``T_field_camera``.

    Thread-safe (one render at a time). Building the BVH takes a fraction of a second at the
    first render; later renders of the same scene reuse it.
    """

    def __init__(
        self, scene: Scene, intrinsics: Intrinsics, sensor: SensorModel | None = None
    ) -> None:
        self.scene = scene
        self.intrinsics = intrinsics
        self.sensor = sensor or SensorModel()
        rays_camera = ray_table(intrinsics, self.sensor.supersample)
        self._rays_camera_t = np.ascontiguousarray(rays_camera.T)  # (3, N) for rotate_t
        self._ray_norms = np.linalg.norm(rays_camera, axis=1)
        self._lock = threading.Lock()
        self._raycaster = scene_raycaster(scene)
        triangles: list[NDArray[np.int64]] = []
        offsets: list[int] = []
        vertex_count = 0
        for body in scene.bodies:
            offsets.append(sum(len(t) for t in triangles))
            triangles.append(body.triangles.astype(np.int64) + vertex_count)
            vertex_count += len(body.vertices_m)
        self._triangles = np.concatenate(triangles)
        self._triangle_offset = np.array(offsets, np.int64)
        self._rgb = np.concatenate([b.albedo_rgb for b in scene.bodies]).astype(np.float32)
        self._ir = np.concatenate([b.albedo_ir for b in scene.bodies]).astype(np.float32)
        self._textured = [(i, b.texture) for i, b in enumerate(scene.bodies) if b.texture]
        self._is_textured = np.array([b.texture is not None for b in scene.bodies], bool)
        self._is_uniform = np.array([_uniform(b) for b in scene.bodies], bool) & ~self._is_textured
        self._body_rgb = np.array([b.albedo_rgb[0] for b in scene.bodies], np.float32)
        self._body_ir = np.array([b.albedo_ir[0] for b in scene.bodies], np.float32)
        sun_az, sun_el = (
            np.radians(self.sensor.sun_azimuth_deg),
            np.radians(self.sensor.sun_elevation_deg),
        )
        self._sun = np.array(
            [np.cos(sun_el) * np.cos(sun_az), np.cos(sun_el) * np.sin(sun_az), np.sin(sun_el)],
            np.float32,
        )
        self._shadow_map = ShadowMap(scene, self._sun)

    @property
    def raycaster(self) -> o3d.t.geometry.RaycastingScene:
        """The scene's bodies in order (geometry id = index in ``scene.bodies``)."""
        return self._raycaster

    def render(self, T_field_camera: Matrix4, rng: np.random.Generator | None = None) -> Frame:
        """One frame (depth_m float32 NaN = missing, color uint8 RGB, ir uint16)."""
        rng = rng or np.random.default_rng()
        sunny = self.sensor.noise and self.sensor.sun_ir > 0
        with self._lock:
            hits = self._cast(T_field_camera)
            light = self._light(hits) if self.sensor.color or sunny else None
        s, h, w = self.sensor.supersample, self.intrinsics.height, self.intrinsics.width
        depth = _pixels(hits.t, h, w, s)
        ir = _pixels(self._ir_amplitude(hits), h, w, s)
        if self.sensor.color and light is not None:
            color = _pixels(self._shade(hits, light), h, w, s)
        else:
            color = np.zeros((h, w, 3), np.float32)
        cos_incidence = _pixels(hits.cos_incidence, h, w, s)
        if self.sensor.noise:
            ir *= 1.0 + self.sensor.ir_noise * rng.standard_normal(ir.shape, np.float32)
            ambient = None
            if sunny and light is not None:
                sun_ir = np.float32(self.sensor.sun_ir)
                ambient = _pixels(
                    np.where(np.isfinite(hits.t), hits.ir * light * sun_ir, 0), h, w, s
                )
            depth = sensor_depth(self.sensor, depth, cos_incidence, ir, rng, ambient)
        else:
            depth[~np.isfinite(depth)] = np.nan
        depth += np.float32(self.sensor.depth_offset_m)
        depth[(depth < MIN_RANGE_M) | (depth > MAX_RANGE_M)] = np.nan
        return Frame(
            depth_m=depth,
            color=_to_srgb8(color, rng if self.sensor.noise else None, self.sensor.color_noise),
            ir=np.clip(ir, 0, 65535).astype(np.uint16),
            meta={COS_INCIDENCE: cos_incidence},
        )

    def _cast(self, T_field_camera: Matrix4) -> Hits:
        R = T_field_camera[:3, :3].astype(np.float32)
        origin = T_field_camera[:3, 3].astype(np.float32)
        directions = rotate_t(R, self._rays_camera_t)
        rays = np.empty((len(directions), 6), np.float32)
        rays[:, :3] = origin
        rays[:, 3:] = directions
        result = self._raycaster.cast_rays(tensor(rays), nthreads=0)
        t = result["t_hit"].numpy()
        hit = np.isfinite(t)
        gid = result["geometry_ids"].numpy().astype(np.int64)
        normals = result["primitive_normals"].numpy()
        facing = np.einsum("ij,ij->i", normals, directions) / -self._ray_norms
        normals *= np.where(facing < 0, np.float32(-1), np.float32(1))[:, None]  # two-sided
        points = (origin + np.where(hit, t, np.float32(0))[:, None] * directions).astype(
            np.float32, copy=False
        )
        rgb, ir = self._albedo(hit, gid, result, points)
        range_m = np.where(hit, t * self._ray_norms, np.float32(np.inf))
        body = np.where(hit, gid, 0)
        return Hits(t, points, normals, np.abs(facing), range_m, rgb, ir, body)

    def _albedo(
        self,
        hit: NDArray[np.bool_],
        gid: NDArray[np.int64],
        result: dict[str, o3d.core.Tensor],
        points: NDArray[np.floating],
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        n = len(hit)
        rgb, ir = np.zeros((n, 3), np.float32), np.zeros(n, np.float32)
        index = np.flatnonzero(hit)
        body = gid[index]
        uniform = self._is_uniform[body]
        rgb[index[uniform]] = self._body_rgb[body[uniform]]
        ir[index[uniform]] = self._body_ir[body[uniform]]
        varied = index[~uniform & ~self._is_textured[body]]
        tri = self._triangle_offset[gid[varied]] + result["primitive_ids"].numpy()[varied]
        corners = self._triangles[tri]
        uv = result["primitive_uvs"].numpy()[varied]
        weights = np.column_stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]])
        rgb[varied] = np.einsum("nk,nkc->nc", weights, self._rgb[corners])
        ir[varied] = np.einsum("nk,nk->n", weights, self._ir[corners])
        for body_index, texture in self._textured:
            on_body = index[gid[index] == body_index]
            if len(on_body):  # the soil: most of a frame (take and row views: 3x faster)
                texture_rgb, ir[on_body] = texture(points.take(on_body, axis=0))
                _rows(rgb)[on_body] = _rows(np.ascontiguousarray(texture_rgb, np.float32))
        return rgb, ir

    def _shade(self, hits: Hits, light: NDArray[np.float32]) -> NDArray[np.float32]:
        """Linear RGB (N, 3): albedo x ``light``; haze where nothing is hit."""
        rgb = hits.rgb * light[:, None]
        rgb[~np.isfinite(hits.t)] = (0.55, 0.62, 0.70)  # haze beyond the modelled ground
        return rgb

    def _light(self, hits: Hits) -> NDArray[np.float32]:
        """Light falling on each hit (N,), white albedo: sky + sun x cos x unshadowed."""
        hit = np.isfinite(hits.t)
        n, sun = hits.normals, self._sun
        cos_sun = np.clip(n[:, 0] * sun[0] + n[:, 1] * sun[1] + n[:, 2] * sun[2], 0.0, 1.0)
        lit = np.zeros(len(hits.t), np.float32)
        lit_side = hit & (cos_sun > 0)
        if self.sensor.shadows:
            lit[lit_side] = cos_sun[lit_side]  # unless a shadow ray is blocked, below
            lit_side &= self._shadow_map.may_be_shadowed(hits.points, hits.body)
        facing = np.flatnonzero(lit_side)
        if len(facing) and self.sensor.shadows:
            rays = np.empty((len(facing), 6), np.float32)
            rays[:, :3] = hits.points[facing] + np.float32(0.002) * hits.normals[facing]
            rays[:, 3:] = self._sun
            occluded = self._raycaster.test_occlusions(tensor(rays), nthreads=0).numpy()
            lit[facing] = np.where(occluded, 0.0, cos_sun[facing])
        elif len(facing):
            lit[facing] = cos_sun[facing]
        light: NDArray[np.float32] = (
            np.float32(self.sensor.sky) * (0.6 + 0.4 * hits.normals[:, 2]) + lit
        )
        return light

    def _ir_amplitude(self, hits: Hits) -> NDArray[np.float32]:
        """Returned IR (N,): albedo x cos(incidence) / range^2, 0 where nothing is hit."""
        near = np.maximum(hits.range_m, np.float32(0.2))
        amplitude: NDArray[np.float32] = hits.ir * hits.cos_incidence / near**2
        return amplitude * np.float32(self.sensor.ir_gain)


def _rows(array: NDArray[np.float32]) -> NDArray[np.void]:
    """A C-contiguous (N, K) array seen as (N, 1) rows of one opaque item each: numpy
    scatters whole rows into it by index several times faster than float by float."""
    return array.view(np.dtype((np.void, array.shape[1] * array.itemsize)))


def _uniform(body: Body) -> bool:
    """Whether a body has one albedo all over (no interpolation needed)."""
    same_rgb = np.all(body.albedo_rgb == body.albedo_rgb[0])
    return bool(same_rgb and np.all(body.albedo_ir == body.albedo_ir[0]))


def _pixels(values: NDArray[np.float32], h: int, w: int, s: int) -> NDArray[np.float32]:
    """Per-ray values (N, ...) to an image (H, W, ...), averaging ``s`` x ``s`` sub-rays."""
    image = np.asarray(values, np.float32).reshape(h, w, s * s, *values.shape[1:])
    if s == 1:
        return image[:, :, 0].copy()
    with np.errstate(invalid="ignore"):
        return image.mean(axis=2, dtype=np.float32)  # type: ignore[no-any-return]


_SRGB_LEVELS = 2048
_SRGB_TABLE = np.clip(
    (np.arange(_SRGB_LEVELS) / (_SRGB_LEVELS - 1)) ** (1 / 2.2) * 255.0 + 0.5, 0, 255
).astype(np.uint8)


def _to_srgb8(
    linear: NDArray[np.float32], rng: np.random.Generator | None, channel_noise: float = 0.0
) -> NDArray[np.uint8]:
    """Linear RGB 0-1 (H, W, 3) to 8-bit (gamma 2.2, by table) with a little sensor noise: 3 %
    of brightness per pixel, and ``channel_noise`` levels (standard deviation) per channel."""
    if rng is not None:
        linear = (
            linear * (1.0 + 0.03 * rng.standard_normal(linear.shape[:2], np.float32))[..., None]
        )
    index = np.clip(linear * (_SRGB_LEVELS - 1), 0, _SRGB_LEVELS - 1).astype(np.int32)
    srgb = _SRGB_TABLE[index]
    if rng is None or channel_noise <= 0.0:
        return srgb
    noisy = srgb + channel_noise * rng.standard_normal(srgb.shape, np.float32)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
