"""The simulator's clods (``simulate --clods``) and per-channel colour noise
(``--color-noise``): what the reconstruction's noise floors are tested against
(``tests/fieldapp/recon/test_colour_noise.py``)."""

from __future__ import annotations

import numpy as np

from devices.sim.render import _to_srgb8
from devices.sim.scene import CLOD_CLEAR_OF_STEMS_M, CLOD_PROTRUSION_M, plot_scene


def test_clods_stand_out_of_the_soil_clear_of_the_stems() -> None:
    plain, cloddy = plot_scene(1), plot_scene(1, clods_per_m2=20)
    assert [b.name for b in cloddy.bodies] == [b.name for b in plain.bodies] + ["clods"]
    clods = cloddy.bodies[-1]
    assert clods.kind == "soil"
    xy = clods.vertices_m[:, :2]
    stems = np.array([[p.x_m, p.y_m] for p in cloddy.plants])
    nearest = np.min(np.linalg.norm(xy[:, None] - stems[None], axis=2), axis=1)
    assert nearest.min() >= CLOD_CLEAR_OF_STEMS_M
    assert cloddy.soil is not None
    above = clods.vertices_m[:, 2] - cloddy.soil.height_m(xy[:, 0], xy[:, 1])
    assert CLOD_PROTRUSION_M[0] < above.max() <= CLOD_PROTRUSION_M[1] + 0.01  # the soil's slope
    assert (
        clods.albedo_rgb.mean(axis=0) < 0.95 * cloddy.soil.albedo(clods.vertices_m)[0].mean(axis=0)
    ).all()
    area = (2 * (cloddy.soil.spec.half_extent_m - 2.0)) ** 2
    assert 0.95 * 20 * area <= len(clods.triangles) / 80 <= 20 * area  # 80 triangles a clod


def test_colour_noise_is_each_channel_s_own() -> None:
    grey = np.full((100, 100, 3), 0.05, np.float32)  # dark: about 60 of 255
    brightness_only = _to_srgb8(grey, np.random.default_rng(0)).astype(int)
    assert (brightness_only[..., 0] == brightness_only[..., 1]).all()  # the hue never changes
    per_channel = _to_srgb8(grey, np.random.default_rng(0), 4.0).astype(int)
    spread = np.std(per_channel[..., 1] - per_channel[..., 0])
    assert 4.0 * np.sqrt(2) * 0.9 < spread < 4.0 * np.sqrt(2) * 1.1


def _widest_across_m(clods) -> float:
    """The widest clod's plan extent (each clod: 42 vertices of a unit sphere's mesh)."""
    xy = clods.vertices_m[:, :2].reshape(-1, 42, 2)
    return float((xy.max(axis=1) - xy.min(axis=1)).max())


def test_a_coarse_seedbed_has_larger_clods_and_the_default_is_unchanged() -> None:
    """``--clod-size 14``: clods up to 14 cm across, as a coarse seedbed's (an independent
    renderer's reach 10 cm), whose tops low leaves rest on; without it, the clods of before."""
    default = plot_scene(1, clods_per_m2=20).bodies[-1]
    same = plot_scene(1, clods_per_m2=20, clod_size_m=0.08).bodies[-1]
    coarse = plot_scene(1, clods_per_m2=20, clod_size_m=0.14).bodies[-1]
    assert _widest_across_m(default) <= 0.08 < _widest_across_m(coarse) <= 0.14
    np.testing.assert_array_equal(default.vertices_m, same.vertices_m)
    scene = plot_scene(1, clods_per_m2=20, clod_size_m=0.14)
    stems = np.array([[p.x_m, p.y_m] for p in scene.plants])
    xy = coarse.vertices_m[:, :2]
    nearest = np.min(np.linalg.norm(xy[:, None] - stems[None], axis=2), axis=1)
    assert nearest.min() >= CLOD_CLEAR_OF_STEMS_M
