"""Synthetic clouds with known geometry for the stage tests."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fieldapp.recon.cloud import Cloud

SOIL_RGB = (120, 90, 60)
LEAF_RGB = (50, 110, 25)


def ground_patch(
    rng: np.random.Generator, half_m: float, n: int, noise_m: float = 0.001
) -> NDArray[np.float64]:
    """(n, 3) points on z = 0 over a square of half size ``half_m``, with z noise."""
    xy = rng.uniform(-half_m, half_m, (n, 2))
    return np.column_stack([xy, rng.normal(0.0, noise_m, n)])


def cylinder(
    rng: np.random.Generator, x_m: float, y_m: float, radius_m: float, height_m: float, n: int
) -> NDArray[np.float64]:
    """(n, 3) points on the side of an upright cylinder standing on z = 0, plus its top disc."""
    side = n * 3 // 4
    angle = rng.uniform(0, 2 * np.pi, side)
    z = rng.uniform(0.0, height_m, side)
    top_r = radius_m * np.sqrt(rng.uniform(0, 1, n - side))
    top_a = rng.uniform(0, 2 * np.pi, n - side)
    return np.concatenate(
        [
            np.column_stack([x_m + radius_m * np.cos(angle), y_m + radius_m * np.sin(angle), z]),
            np.column_stack(
                [
                    x_m + top_r * np.cos(top_a),
                    y_m + top_r * np.sin(top_a),
                    np.full(n - side, height_m),
                ]
            ),
        ]
    )


def colored(points: NDArray[np.float64], rgb: tuple[int, int, int]) -> Cloud:
    return Cloud(points, np.tile(np.array(rgb, np.uint8), (len(points), 1)))


def seedling(
    rng: np.random.Generator, x_m: float, y_m: float, width_m: float, height_m: float, n: int
) -> NDArray[np.float64]:
    """(n, 3) a stylised seedling standing at (x, y) on z = 0: a thin stem of ``height_m``
    and a flat leaf disc of diameter ``width_m`` (rim included) at 60 % of the height."""
    stem = cylinder(rng, x_m, y_m, 0.008, height_m, n // 3)
    disc_n = n - len(stem)
    rim = disc_n // 5
    radius = np.concatenate(
        [np.full(rim, width_m / 2), np.sqrt(rng.uniform(0.02, 1.0, disc_n - rim)) * width_m / 2]
    )
    angle = rng.uniform(0, 2 * np.pi, disc_n)
    disc = np.column_stack(
        [
            x_m + radius * np.cos(angle),
            y_m + radius * np.sin(angle),
            np.full(disc_n, 0.6 * height_m),
        ]
    )
    return np.concatenate([stem, disc])
