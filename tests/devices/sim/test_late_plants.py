"""``simulate --late-plants``: plants that came up late, seedlings among grown neighbours.

Uneven emergence (a cold spell, a dry seedbed, a seed sown too deep) leaves a field's later
scans with small plants among tall ones, whose low leaves can reach over them. Built so the
plants step is tested on it: a small plant beside a tall one must stay a plant, and its
neighbour's leaves must not make it larger.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.sim.scene import PlotLayout, late_draws, plot_scene
from fieldapp.cli import main

SMALL = PlotLayout(rows=2, cols=3)
"""Six plants: enough to draw late and grown ones, a sixth of the standard plot's time."""


def test_no_late_plant_leaves_the_plot_as_it_was() -> None:
    plain = plot_scene(4, layout=SMALL, stage="touching")
    none = plot_scene(4, layout=SMALL, stage="touching", late_plants=0.0)
    for a, b in zip(plain.bodies, none.bodies, strict=True):
        np.testing.assert_array_equal(a.vertices_m, b.vertices_m)
    assert not late_draws(4, 16, 0.0).any() and late_draws(4, 16, 1.0).all()
    with pytest.raises(ValueError, match="late plants"):
        late_draws(4, 16, 1.5)


def test_late_plants_are_seedlings_standing_where_their_row_put_them() -> None:
    """The late plants are the seedlings of the plot's seedling stage (same draws, so each is
    the plant the seedling plot has there); a larger chance makes more of the same plants late;
    every plant stands where it stood."""
    seedlings = plot_scene(2, layout=SMALL)
    grown = plot_scene(2, layout=SMALL, stage="touching")
    some = plot_scene(2, layout=SMALL, stage="touching", late_plants=0.3)
    more = plot_scene(2, layout=SMALL, stage="touching", late_plants=0.7)
    late_some, late_more = late_draws(2, 6, 0.3), late_draws(2, 6, 0.7)
    assert 0 < late_some.sum() < late_more.sum() < 6
    assert np.all(late_more[late_some])
    for i, plant in enumerate(some.plants):
        expected = seedlings.plants[i] if late_some[i] else grown.plants[i]
        assert plant.height_cm == pytest.approx(expected.height_cm)
        assert (plant.x_m, plant.y_m) == pytest.approx((grown.plants[i].x_m, grown.plants[i].y_m))
    heights = np.array([p.height_cm for p in more.plants])
    assert heights[late_more].max() < 40.0 < heights[~late_more].min()


def test_simulate_records_the_late_plants_and_refuses_them_off_the_touching_stage(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "late"
    options = ["--grid", "2", "--stations", "1", "--views", "0", "--late-plants", "0.5"]
    assert main(["simulate", "--out", str(out), "--stage", "touching", *options]) == 0
    assert json.loads((out / "truth.json").read_text())["late_plants"] == 0.5
    assert main(["simulate", "--out", str(tmp_path / "s"), "--late-plants", "0.5"]) == 1
    assert "--late-plants: only at --stage touching" in capsys.readouterr().err
    soil = ["simulate", "--out", str(tmp_path / "soil"), "--scene", "soil"]
    assert main([*soil, "--late-plants", "0.5"]) == 1
    touching = ["simulate", "--out", str(tmp_path / "x"), "--stage", "touching"]
    assert main([*touching, "--late-plants", "2"]) == 1
    assert "--late-plants: 2 is outside 0..1" in capsys.readouterr().err
