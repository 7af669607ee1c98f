"""A reconstructed cloud of the simulator's six reference spheres, sampled with Kinect-like
noise: what the stations on a ring around the plot see of each sphere, each point moved along
its line of sight by the Kinect v2 axial noise at its range and incidence, 2 % flying pixels,
and bumpy soil."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from devices.sim.render import axial_noise_m
from devices.sim.scene import SPHERE_DIAMETERS_MM, SPHERE_SPOTS_M

SPACING_M = 0.006


def sphere_truth() -> list[tuple[float, NDArray[np.float64]]]:
    """(diameter_mm, centre) as the simulator places them (on flat ground here)."""
    diameters = sorted(SPHERE_DIAMETERS_MM, reverse=True)
    return [
        (float(d), np.array([x, y, d / 2000.0]))
        for (x, y), d in zip(SPHERE_SPOTS_M, diameters, strict=True)
    ]


def cameras() -> NDArray[np.float64]:
    angles = np.radians(np.arange(0, 360, 45))
    return np.stack([1.6 * np.cos(angles), 1.6 * np.sin(angles), np.full(8, 1.3)], axis=1)


def sphere_points(
    center: NDArray[np.float64], radius_m: float, rng: np.random.Generator, skip: float = 0.0
) -> NDArray[np.float64]:
    count = int(4 * np.pi * radius_m**2 / SPACING_M**2)
    normals = rng.normal(size=(count, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    points = center + radius_m * normals
    rays = cameras()[None, :, :] - points[:, None, :]
    ranges = np.linalg.norm(rays, axis=2)
    cosines = np.einsum("nk,nck->nc", normals, rays) / ranges
    visible = cosines > 0.15
    keep = visible.any(axis=1) & (points[:, 2] > 0.02)
    points, cosines, ranges, rays = points[keep], cosines[keep], ranges[keep], rays[keep]
    best = np.argmax(np.where(visible[keep], cosines, -1), axis=1)
    index = np.arange(len(points))
    sigma = axial_noise_m(ranges[index, best], np.arccos(cosines[index, best]))
    direction = rays[index, best] / ranges[index, best][:, None]
    noisy = points + direction * (rng.normal(size=len(points)) * sigma)[:, None]
    flying = rng.random(len(points)) < 0.02
    noisy[flying] += direction[flying] * rng.uniform(-0.05, 0.05, (int(flying.sum()), 1))
    return noisy


def soil_points(rng: np.random.Generator) -> NDArray[np.float64]:
    xy = rng.uniform(-1.8, 1.8, (150_000, 2))
    z = 0.015 * np.sin(3 * xy[:, 0]) * np.cos(2 * xy[:, 1]) + rng.normal(0, 0.003, len(xy))
    return np.column_stack([xy, z])


def sphere_cloud(seed: int, missing_mm: float | None = None) -> NDArray[np.float64]:
    """(N, 3) field-frame cloud of the spheres (without the one of ``missing_mm``) and soil."""
    rng = np.random.default_rng(seed)
    parts = [soil_points(rng)]
    for diameter, center in sphere_truth():
        if diameter != missing_mm:
            parts.append(sphere_points(center, diameter / 2000.0, rng))
    return np.concatenate(parts)
