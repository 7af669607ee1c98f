"""``simulate --dry-tips CM``: every leaf's last centimetres straw brown, the shapes (and the
truth) unchanged; without it, the plants of before."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from devices.sim.plants import DRY_TIP_RGB, LEAF_RGB, make_plant, with_dry_tips
from devices.sim.render import _to_srgb8
from devices.sim.scene import plot_scene
from devices.sim.soil import SOIL_RGB


@pytest.mark.parametrize("model", ["distichous", "irregular"])
def test_the_last_centimetres_of_every_leaf_and_nothing_else_turn_brown(model: str) -> None:
    plant = make_plant(4, 0, (0.0, 0.0), 0.0, "touching", model)
    dry = with_dry_tips(plant, 0.05)
    np.testing.assert_array_equal(dry.vertices_m, plant.vertices_m)
    changed = np.any(dry.albedo_rgb != plant.albedo_rgb, axis=1)
    assert plant.organ_of_vertex is not None
    for leaf in range(plant.leaves):
        at = np.flatnonzero(plant.organ_of_vertex == leaf)
        sections = plant.vertices_m[at].reshape(-1, plant.section_vertices, 3).mean(axis=1)
        steps = np.linalg.norm(np.diff(sections, axis=0), axis=1)
        from_tip = np.concatenate([np.cumsum(steps[::-1])[::-1], [0.0]])
        expected = np.repeat(from_tip < 0.05, plant.section_vertices)
        np.testing.assert_array_equal(changed[at], expected)
        assert from_tip[0] >= 0.05  # a leaf longer than its dry tip keeps its green base
    assert not changed[plant.organ_of_vertex < 0].any()  # the stem stays as it was
    np.testing.assert_allclose(dry.albedo_rgb[changed], np.tile(DRY_TIP_RGB, (changed.sum(), 1)))


def test_dry_tan_is_as_little_green_as_the_soil_in_the_image() -> None:
    """As the camera writes them (gamma, 8 bits), the dry tip's excess green is the loam's
    (0.004 against 0.0): under every colour threshold measured (0.02 on this simulator's
    plots, 0.1-0.25 on the renderers'), where a leaf's is 0.2-0.5."""

    def excess_green(linear: NDArray[np.float32]) -> float:
        r, g, b = _to_srgb8(linear.reshape(1, 1, 3), None).reshape(3).astype(float)
        return (2 * g - r - b) / (r + g + b)

    assert abs(excess_green(DRY_TIP_RGB) - excess_green(SOIL_RGB)) < 0.01
    assert excess_green(DRY_TIP_RGB) < 0.02 < 0.2 < excess_green(LEAF_RGB)


def test_the_scene_s_truth_is_that_of_green_plants_and_the_default_is_unchanged() -> None:
    green = plot_scene(2, stage="touching")
    dry = plot_scene(2, stage="touching", dry_tips_m=0.08)
    same = plot_scene(2, stage="touching", dry_tips_m=0.0)
    assert [p.width_cm for p in dry.plants] == [p.width_cm for p in green.plants]
    for a, b, c in zip(green.bodies, dry.bodies, same.bodies, strict=True):
        np.testing.assert_array_equal(a.vertices_m, b.vertices_m)
        np.testing.assert_array_equal(a.albedo_rgb, c.albedo_rgb)
    assert any(
        not np.array_equal(a.albedo_rgb, b.albedo_rgb)
        for a, b in zip(green.bodies, dry.bodies, strict=True)
    )


def test_dry_tips_out_of_range_are_refused() -> None:
    plant = make_plant(4, 0, (0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="dry tips"):
        with_dry_tips(plant, 0.5)
