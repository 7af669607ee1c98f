"""Excess green in integers (issue 22) gives the values of the float64 formula, bit for bit:
the reconstruction's outputs did not change with it."""

from __future__ import annotations

import numpy as np

from fieldapp.recon.filters import excess_green


def _float64_formula(colors: np.ndarray) -> np.ndarray:
    rgb = colors.astype(np.float64)
    total = rgb.sum(axis=1)
    total[total == 0] = 1.0
    return (2.0 * rgb[:, 1] - rgb[:, 0] - rgb[:, 2]) / total


def test_integer_excess_green_equals_the_float64_formula_bit_for_bit() -> None:
    rng = np.random.default_rng(22)
    levels = np.array([0, 1, 2, 127, 128, 254, 255], np.uint8)
    corners = np.stack(np.meshgrid(levels, levels, levels), axis=-1).reshape(-1, 3)
    colors = np.concatenate([corners, rng.integers(0, 256, (200_000, 3), dtype=np.uint8)])
    exg = excess_green(colors)
    assert exg.dtype == np.float64
    np.testing.assert_array_equal(exg.view(np.int64), _float64_formula(colors).view(np.int64))
    assert exg[0] == 0.0 and exg.min() >= -1.0 and exg.max() <= 2.0
