"""``SensorModel.veil_px`` (``fieldapp simulate --veil PX``): flying pixels as a veil several
pixels deep beside every depth edge, stepping evenly from the near surface to the far one, as an
independent renderer's (and a time-of-flight camera's smoothed) edges give them; the
reconstruction flags the veil's pixels (``scans.mixed_pixels``) so they do not set a width."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from devices.sim.render import SensorModel
from devices.sim.sensor import sensor_depth, veiled
from fieldapp.recon.scans import CONTINUOUS_SHARE, DepthEdges, mixed_pixels

LEAF_M, LOWER_M, SOIL_M = 1.0, 1.15, 1.6


def _leaf_over(behind_m: float) -> np.ndarray:
    depth = np.full((30, 40), behind_m, np.float32)
    depth[:, :15] = LEAF_M
    return depth


def test_a_veil_steps_evenly_from_the_near_edge_to_the_far_surface() -> None:
    veil = veiled(_leaf_over(SOIL_M), 3, SensorModel().edge_jump)
    row = veil[15, 13:21].tolist()
    assert np.allclose(row, [1.0, 1.0, 1.15, 1.3, 1.45, 1.6, 1.6, 1.6], atol=1e-6)
    assert np.array_equal(veiled(_leaf_over(SOIL_M), 0, 0.04), _leaf_over(SOIL_M))


def test_a_surface_sloping_away_and_nothing_hit_spread_no_veil() -> None:
    sloping = np.tile((LEAF_M * 1.015 ** np.arange(40)).astype(np.float32), (30, 1))
    assert np.array_equal(veiled(sloping, 4, 0.04), sloping)
    sky = _leaf_over(np.inf)
    assert np.array_equal(veiled(sky, 3, 0.04), sky)  # nothing behind the edge: no veil


def test_a_gentle_veil_over_a_lower_leaf_is_flagged_as_mixed_pixels() -> None:
    """A veil four deep between a leaf and a lower leaf 15 cm behind it steps 3 cm (2-3 % of
    its distance) a pixel: under the share that tells surfaces apart, still between two."""
    depth = veiled(_leaf_over(LOWER_M), 4, SensorModel().edge_jump)
    steps = np.diff(depth[15, 14:20]) / depth[15, 15:20]
    assert ((steps > 0.02) & (steps < CONTINUOUS_SHARE)).all()
    pixels = np.arange(15 * 40 + 12, 15 * 40 + 22, dtype=np.intp)
    flags = mixed_pixels(DepthEdges.of(depth, np.isfinite(depth)), pixels)
    assert flags.tolist() == [False] * 3 + [True] * 4 + [False] * 3


def test_the_sensor_adds_its_noise_on_the_veil() -> None:
    depth = _leaf_over(SOIL_M)
    facing = np.ones(depth.shape, np.float32)
    ir = np.full(depth.shape, 1000.0, np.float32)
    sensor = SensorModel(flying_fraction=0.0, veil_px=3)
    noisy = sensor_depth(sensor, depth, facing, ir, np.random.default_rng(0))
    assert abs(np.nanmedian(noisy[:, 16]) - 1.3) < 0.005  # a third of the way: 1.0 -> 1.6
    plain = replace(sensor, veil_px=0)
    alone = sensor_depth(plain, depth, facing, ir, np.random.default_rng(0))
    assert abs(np.nanmedian(alone[:, 16]) - SOIL_M) < 0.005
