"""Uneven soil: a seeded heightfield (a few cm of relief, z = 0 on its mean) and its texture.

All coordinates are in the field frame: z up, metres, origin at the plot centre.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

SOIL_RGB = np.array([0.30, 0.19, 0.11], dtype=np.float32)
"""Mean albedo of dry loam in the colour image (linear 0-1 RGB)."""

SOIL_IR = 0.30
"""Mean near-infrared albedo of soil (the Kinect's 860 nm)."""


@dataclass(frozen=True)
class SoilSpec:
    """How the soil is drawn. ``relief_m`` is the standard deviation of the large bumps."""

    half_extent_m: float = 8.0
    spacing_m: float = 0.04
    relief_m: float = 0.015
    clod_m: float = 0.002
    texture_px: int = 2048


@dataclass
class Soil:
    """A seeded heightfield: :meth:`height_m` is analytic, :meth:`mesh` samples it on a grid."""

    spec: SoilSpec
    seed: int
    _waves: NDArray[np.float64] = field(init=False, repr=False)
    _offset_m: float = field(init=False, repr=False, default=0.0)
    _texture: NDArray[np.float32] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        rng = np.random.default_rng([self.seed, 101])
        self._waves = np.concatenate(
            [
                _waves(rng, 12, 0.8, 4.0, self.spec.relief_m),
                _waves(rng, 24, 0.06, 0.2, self.spec.clod_m),
            ]
        )
        self._offset_m = 0.0
        self._offset_m = float(self.height_m(*self._grid_xy()).mean())
        self._texture = _texture(rng, self.spec.texture_px)

    def height_m(self, x_m: NDArray[np.float64], y_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Ground height (m) at field points ``x_m``, ``y_m`` (any matching shapes)."""
        x, y = np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64)
        z = np.zeros(np.broadcast(x, y).shape)
        for kx, ky, amplitude, phase in self._waves:
            z += amplitude * np.sin(kx * x + ky * y + phase)
        return z - self._offset_m

    def height_at(self, x_m: float, y_m: float) -> float:
        """Ground height (m) at one field point."""
        return float(self.height_m(np.array(x_m), np.array(y_m)))

    def _grid_xy(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        n = round(2 * self.spec.half_extent_m / self.spec.spacing_m) + 1
        axis = np.linspace(-self.spec.half_extent_m, self.spec.half_extent_m, n)
        return np.meshgrid(axis, axis)

    def mesh(self) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
        """The heightfield as a triangle mesh: vertices (V, 3) float64, triangles (T, 3) int32."""
        X, Y = self._grid_xy()
        n = X.shape[0]
        vertices = np.stack([X.ravel(), Y.ravel(), self.height_m(X, Y).ravel()], axis=1)
        i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
        a = (i * n + j).ravel()
        triangles = np.concatenate(
            [np.stack([a, a + 1, a + n], 1), np.stack([a + 1, a + n + 1, a + n], 1)]
        )
        return vertices, triangles.astype(np.int32)

    def albedo(
        self, points_m: NDArray[np.floating]
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Colour (N, 3) float32 0-1 and NIR albedo (N,) of the soil at ``points_m`` (N, 3)."""
        size = self.spec.texture_px
        scale = (size - 1) / (2 * self.spec.half_extent_m)
        u = np.clip(
            ((points_m[:, 0] + self.spec.half_extent_m) * scale).astype(np.int64), 0, size - 1
        )
        v = np.clip(
            ((points_m[:, 1] + self.spec.half_extent_m) * scale).astype(np.int64), 0, size - 1
        )
        shade = self._texture.ravel()[v * size + u]
        rgb = np.empty((len(shade), 3), np.float32)
        np.multiply(SOIL_RGB[0], shade, out=rgb[:, 0])
        rgb[:, 0] *= 1.0 + 0.08 * (shade - 1.0)  # darker patches are also redder (moister)
        np.multiply(SOIL_RGB[1], shade, out=rgb[:, 1])
        np.multiply(SOIL_RGB[2], shade, out=rgb[:, 2])
        return rgb, np.float32(SOIL_IR) * shade


def _waves(
    rng: np.random.Generator, count: int, shortest_m: float, longest_m: float, rms_m: float
) -> NDArray[np.float64]:
    """(count, 4) rows of kx, ky (rad/m), amplitude (m), phase: random plane waves of total RMS."""
    wavelength = np.exp(rng.uniform(np.log(shortest_m), np.log(longest_m), count))
    direction = rng.uniform(0.0, 2 * np.pi, count)
    k = 2 * np.pi / wavelength
    amplitude = rng.uniform(0.5, 1.0, count) * wavelength  # longer waves carry more relief
    amplitude *= rms_m / np.sqrt(0.5 * np.sum(amplitude**2)) if rms_m > 0 else 0.0
    phase = rng.uniform(0.0, 2 * np.pi, count)
    return np.stack([k * np.cos(direction), k * np.sin(direction), amplitude, phase], axis=1)


def _texture(rng: np.random.Generator, size: int) -> NDArray[np.float32]:
    """(size, size) float32 multiplicative albedo around 1: clumps, pebbles, crumbs."""
    texture = np.ones((size, size), np.float32)
    for cells, weight in ((16, 0.10), (96, 0.10), (512, 0.08), (size, 0.10)):
        noise = rng.standard_normal((cells, cells)).astype(np.float32)
        texture += weight * cv2.resize(noise, (size, size), interpolation=cv2.INTER_CUBIC)
    pebbles = (rng.random((size, size)) < 0.003).astype(np.float32)
    texture += 0.5 * cv2.GaussianBlur(pebbles, (5, 5), 0.8) / 0.2  # small light stones
    return np.clip(texture, 0.45, 1.6)
