"""``simulate --grounded-leaves``: lower leaves that arch over and come down to the soil.

An independent renderer's tall plants had low leaves arching to the ground, and the plants step
took such a leaf's end for a stem of its own; this simulator's leaves never came down steeply
enough to show it (``docs/RECONSTRUCTION.md`` "Leaves down to the soil").
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from devices.sim.plants import (
    MAX_LEAVES,
    PLANT_MODELS,
    grounded_draws,
    make_plant,
)
from devices.sim.scene import plot_scene
from fieldapp.cli import main


def _leaves(
    vertices: NDArray[np.float64], organ: NDArray[np.int16] | None
) -> dict[int, NDArray[np.float64]]:
    assert organ is not None
    return {int(k): vertices[organ == k] for k in np.unique(organ[organ >= 0])}


@pytest.mark.parametrize("model", PLANT_MODELS)
def test_grounded_leaves_come_down_to_the_soil_steeply_away_from_the_stem(model: str) -> None:
    """Every grounded leaf (of the lower half) reaches under the ground, its last 15 cm above
    it coming down nearly straight, 8-55 cm from the stem; the other leaves are as they were."""
    reached, radii = 0, []
    for seed in range(6):
        plain = make_plant(seed, 0, (0.0, 0.0), 0.0, "touching", model)
        down = make_plant(seed, 0, (0.0, 0.0), 0.0, "touching", model, grounded_leaves=1.0)
        before = _leaves(plain.vertices_m, plain.organ_of_vertex)
        after = _leaves(down.vertices_m, down.organ_of_vertex)
        assert before.keys() == after.keys()
        lower = [k for k in before if k <= (len(before) - 1) / 2]
        for k, leaf in after.items():
            if k not in lower:
                np.testing.assert_array_equal(leaf, before[k])
                continue
            under = leaf[leaf[:, 2] < 0.0]
            if len(under) == 0:  # a low, flat leaf that turned down within its node's height
                continue
            reached += 1
            radii.append(float(np.hypot(under[:, 0], under[:, 1]).min()))
        assert down.organ_of_vertex is not None
        stem = down.organ_of_vertex < 0
        np.testing.assert_array_equal(down.vertices_m[stem], plain.vertices_m[stem])
    assert reached >= 6
    assert min(radii) >= 0.08 and max(radii) <= 0.55


def test_no_grounded_leaf_leaves_the_plants_as_they_were() -> None:
    for model in PLANT_MODELS:
        a = make_plant(7, 0, (0.3, 0.2), 0.01, "touching", model)
        b = make_plant(7, 0, (0.3, 0.2), 0.01, "touching", model, grounded_leaves=0.0)
        np.testing.assert_array_equal(a.vertices_m, b.vertices_m)
    assert not grounded_draws(7, 0.0).any() and grounded_draws(7, 1.0).all()
    assert len(grounded_draws(7, 0.5)) == MAX_LEAVES
    with pytest.raises(ValueError, match="grounded leaves"):
        grounded_draws(7, 1.5)


def test_grounded_leaves_meet_the_soil_in_the_scene() -> None:
    """On the plot's uneven soil, away from the stems: a leaf coming down to the soil meets it
    there (its tip runs into it, hidden, as :func:`settle_on_ground` leaves what is lower than
    the plant's own foot), on most plants."""
    scene = plot_scene(2, stage="touching", grounded_leaves=1.0)
    assert scene.soil is not None
    resting = 0
    bodies = [b for b in scene.bodies if b.kind == "plant"]
    for body, truth in zip(bodies, scene.plants, strict=True):
        v = body.vertices_m
        away = np.hypot(v[:, 0] - truth.x_m, v[:, 1] - truth.y_m) > 0.08
        height = v[away, 2] - scene.soil.height_m(v[away, 0], v[away, 1])
        resting += int(np.any(np.abs(height) < 0.01))
    assert resting >= 12


def test_simulate_records_the_grounded_leaves_and_refuses_them_off_the_plot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "grounded"
    options = ["--grid", "2", "--stations", "1", "--views", "0", "--grounded-leaves", "0.5"]
    assert main(["simulate", "--out", str(out), "--stage", "touching", *options]) == 0
    assert json.loads((out / "truth.json").read_text())["grounded_leaves"] == 0.5
    soil = ["simulate", "--out", str(tmp_path / "soil"), "--scene", "soil"]
    assert main([*soil, "--grounded-leaves", "0.5"]) == 1
    assert main(["simulate", "--out", str(tmp_path / "x"), "--grounded-leaves", "2"]) == 1
    assert "--grounded-leaves: 2 is outside 0..1" in capsys.readouterr().err
