"""What floats above the soil and is not green is not a plant (``plants._foreign``).

An independent renderer's touching plot had white reference spheres on dark 16 mm stands among
the plants; the cap of one, 67-77 cm up and touching leaves (the weak green grown from them
kept it), became a 77 cm tall "plant" off the grid.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.plants import search_plants
from fieldapp.recon.settings import PlantSettings

from .synthetic import LEAF_RGB, colored, ground_patch
from .touching import plant


def _cap(rng: np.random.Generator, centre: tuple[float, float, float], n: int = 1500) -> NDArray:
    """(n, 3) the upper half of a 12 cm sphere: what the cameras see of it above the leaves."""
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return np.asarray(centre) + 0.062 * v


def _plot(rng: np.random.Generator, cap_rgb: tuple[int, int, int], z_m: float) -> Cloud:
    a = colored(plant(rng, (0.0, 0.0), [(0.0, 0.2, 0.4, 0.12), (180.0, 0.3, 0.4, 0.1)]), LEAF_RGB)
    cap = colored(_cap(rng, (0.7, 0.3, z_m)), cap_rgb)
    return Cloud(np.concatenate([a.points, cap.points]), np.concatenate([a.colors, cap.colors]))


def test_a_sphere_cap_above_the_plants_is_not_a_plant() -> None:
    rng = np.random.default_rng(0)
    soil = ground_patch(rng, 1.2, 30000)
    search = search_plants(_plot(rng, (139, 149, 138), 0.66), soil, PlantSettings(), 0.3)
    assert len(search.plants) == 1
    assert np.hypot(search.plants[0].traits.x_m, search.plants[0].traits.y_m) < 0.03
    assert any("not counted as a plant" in m and "(0.70, 0.30)" in m for m in search.merges)


def test_a_green_group_up_there_is_a_plant_and_so_is_one_near_the_soil() -> None:
    """A green group floating there is a plant's top whose lower part was not seen; a grey one
    near the soil (its lowest point under 15 cm) is left to the other rules."""
    rng = np.random.default_rng(1)
    soil = ground_patch(rng, 1.2, 30000)
    for rgb, z in ((LEAF_RGB, 0.66), ((139, 149, 138), 0.1)):
        search = search_plants(_plot(rng, rgb, z), soil, PlantSettings(), 0.3)
        assert len(search.plants) == 2
        assert not any("not counted as a plant" in m for m in search.merges)


def test_without_colour_nothing_is_dropped_for_its_colour() -> None:
    """Depth-only captures (every point grey, separated by geometry): the colour says nothing."""
    rng = np.random.default_rng(2)
    soil = ground_patch(rng, 1.2, 30000)
    cloud = _plot(rng, (139, 149, 138), 0.66)
    grey = Cloud(cloud.points, np.full_like(cloud.colors, 128))
    assert len(search_plants(grey, soil, PlantSettings(), 0.3).plants) == 2


def test_a_green_top_mostly_without_colour_is_a_plant() -> None:
    """libfreenect2 leaves black (no colour) the pixels its colour camera does not see, bands
    beside every near edge: a plant's top seen apart from its lower part, 60 % of it black,
    is judged by the colour of the rest (green), not by black's excess green (0)."""
    rng = np.random.default_rng(3)
    soil = ground_patch(rng, 1.2, 30000)
    cloud = _plot(rng, LEAF_RGB, 0.66)
    colors = cloud.colors.copy()
    top = np.flatnonzero(np.hypot(cloud.points[:, 0] - 0.7, cloud.points[:, 1] - 0.3) < 0.1)
    colors[top[rng.random(len(top)) < 0.6]] = 0
    search = search_plants(Cloud(cloud.points, colors), soil, PlantSettings(), 0.3)
    assert len(search.plants) == 2
    assert not any("not counted as a plant" in m for m in search.merges)


def _stand_beside_a_leaf(rng: np.random.Generator, rgb: tuple[int, int, int]) -> Cloud:
    """The plant of :func:`_plot` (35 cm stem, its first leaf's tip at x = 0.40 m, 14 cm up)
    and a 16 mm stand 2.2 cm past that tip, from 12 to 60 cm up, under a 12 cm sphere's cap:
    what the cameras kept of a reference sphere on its stand (the foot hidden by the leaves).
    The gap is wider than the plant graph's steps (1.5 cm), narrower than a density cluster's
    (2.5 cm voxels): the stand is not reached along the plant, but shares its cluster."""
    a = colored(plant(rng, (0.0, 0.0), [(0.0, 0.2, 0.4, 0.12), (180.0, 0.3, 0.4, 0.1)]), LEAF_RGB)
    angle = rng.uniform(0.0, 2.0 * np.pi, 1500)
    z = rng.uniform(0.12, 0.6, 1500)
    stand = np.column_stack([0.43 + 0.008 * np.cos(angle), 0.008 * np.sin(angle), z])
    thing = colored(np.concatenate([stand, _cap(rng, (0.43, 0.0, 0.6))]), rgb)
    return Cloud(np.concatenate([a.points, thing.points]), np.concatenate([a.colors, thing.colors]))


def test_a_grey_stand_touching_a_leaf_is_not_joined_to_the_plant() -> None:
    """An independent renderer's reference spheres and their stands touched the leaves of tall
    plants without being reached along them: joined as a leaf seen with a gap at its base
    would be, they raised the plants' heights by up to 24 cm. Grey, white or near black, and
    not green, such a fragment is not joined; a brown one is (a leaf's tip seen with the
    soil's colour), a green one is, and without colour (depth-only) nothing is judged by it."""
    rng = np.random.default_rng(4)
    soil = ground_patch(rng, 1.2, 30000)
    for rgb in ((139, 149, 138), (40, 40, 44), (200, 200, 205)):  # sphere, stand, sunlit cap
        search = search_plants(_stand_beside_a_leaf(rng, rgb), soil, PlantSettings(), 0.3)
        assert len(search.plants) == 1
        assert search.plants[0].traits.height_m < 0.4  # its 35 cm stem, not the 66 cm cap
        assert any("neither green nor of any hue" in m for m in search.merges)
    for rgb in (LEAF_RGB, (120, 90, 59)):
        search = search_plants(_stand_beside_a_leaf(rng, rgb), soil, PlantSettings(), 0.3)
        assert len(search.plants) == 1 and search.plants[0].traits.height_m > 0.6
        assert not any("neither green nor of any hue" in m for m in search.merges)
    cloud = _stand_beside_a_leaf(rng, (139, 149, 138))
    depth_only = Cloud(cloud.points, np.full_like(cloud.colors, 128))
    search = search_plants(depth_only, soil, PlantSettings(), 0.3)
    assert len(search.plants) == 1 and search.plants[0].traits.height_m > 0.6
