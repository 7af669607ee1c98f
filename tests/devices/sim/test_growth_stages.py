"""The simulator grows plants to touching: the ``touching`` stage, its truth, the CLI option."""

from __future__ import annotations

import numpy as np
import pytest

from devices.sim.canopy import PlantSurface, canopy_contacts
from devices.sim.plants import make_plant
from devices.sim.scene import plot_scene
from fieldapp.cli import main


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_touching_stage_plants_are_55_to_90_cm_with_5_to_8_leaves(seed: int) -> None:
    meshes = [make_plant(seed * 1000 + i, 0, (0.0, 0.0), 0.0, "touching") for i in range(16)]
    heights = [m.height_m for m in meshes]
    assert min(heights) >= 0.55 and max(heights) <= 0.90
    assert {m.leaves for m in meshes} <= {5, 6, 7, 8}
    assert np.median([m.width_m for m in meshes]) > 0.9  # spread past the 80 cm spacing


def test_the_seedling_stage_is_the_default_and_unchanged_by_the_touching_draws() -> None:
    seedling = make_plant(7, 10, (0.1, 0.2), 0.01)
    again = make_plant(7, 10, (0.1, 0.2), 0.01, "seedling")
    np.testing.assert_array_equal(seedling.vertices_m, again.vertices_m)
    assert seedling.height_m < 0.55
    with pytest.raises(ValueError, match="stage"):
        make_plant(7, 0, (0.0, 0.0), 0.0, "flowering")


@pytest.mark.parametrize("seed", [0, 1])
def test_touching_plots_touch_and_seedling_plots_do_not(seed: int) -> None:
    grown = plot_scene(seed, stage="touching").contacts()
    assert grown.touching_pairs >= 1
    assert sum(bool(names) for names in grown.reaching_into.values()) >= 12
    for name, others in grown.touching.items():  # symmetric
        assert all(name in grown.touching[other] for other in others)
    seedlings = plot_scene(seed).contacts()
    assert seedlings.touching_pairs == 0 and not any(seedlings.reaching_into.values())


def test_contacts_of_two_ribbons() -> None:
    def ribbon(x0: float, x1: float, z: float) -> PlantSurface:
        vertices = np.array([[x0, -0.05, z], [x1, -0.05, z], [x1, 0.05, z], [x0, 0.05, z]])
        triangles = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
        return PlantSurface(f"{x0}", vertices, triangles, np.array([x0, 0.0, 0.0]))

    touching = canopy_contacts([ribbon(0.0, 0.5, 0.2), ribbon(0.8, 0.3, 0.205)])
    assert touching.touching_pairs == 1
    assert touching.reaching_into == {"0.0": ["0.8"], "0.8": ["0.0"]}
    apart = canopy_contacts([ribbon(0.0, 0.3, 0.2), ribbon(0.8, 0.45, 0.2)])
    assert apart.touching_pairs == 0 and apart.reaching_into == {"0.0": [], "0.8": []}


def test_the_cli_names_a_bad_stage(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--out", str(tmp_path / "s"), "--stage", "late"]) == 1
    assert "--stage: 'late' is not one of seedling, touching" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()
