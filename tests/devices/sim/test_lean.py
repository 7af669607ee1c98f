"""``fieldapp simulate --lean DEG``: plots whose stems lean more than the plant models' own
1-6 degrees, the same plants otherwise."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from devices.sim.organ_truth import _stem_rings
from devices.sim.plants import MAX_LEAN_DEG, PLANT_MODELS, PlantMesh, make_plant
from fieldapp.cli import main

if TYPE_CHECKING:
    from tests.conftest import SimulateRefuses


def lean_deg(mesh: PlantMesh) -> float:
    """The stem's angle from the vertical (bottom ring's centre to the top one's)."""
    centres, _ = _stem_rings(mesh)
    axis = centres[-1] - centres[0]
    return float(np.degrees(np.arccos(axis[2] / np.linalg.norm(axis))))


@pytest.mark.parametrize("model", PLANT_MODELS)
@pytest.mark.parametrize("stage", ["seedling", "touching"])
def test_a_plant_leans_its_own_share_of_the_largest_lean(model: str, stage: str) -> None:
    for seed in range(6):
        own = make_plant(seed, 0, (0.0, 0.0), 0.0, stage, model)
        more = make_plant(seed, 0, (0.0, 0.0), 0.0, stage, model, 24.0)
        upright = make_plant(seed, 0, (0.0, 0.0), 0.0, stage, model, 0.0)
        top = 5.0 if model == "distichous" else 6.0  # the models' own largest leans
        assert 0.0 <= lean_deg(own) <= top + 0.1
        assert lean_deg(more) == pytest.approx(lean_deg(own) * 24.0 / top, abs=0.2)
        assert lean_deg(upright) < 0.1
        assert own.leaves == more.leaves == upright.leaves  # the same plant, leaning more
        height = own.vertices_m[:, 2].max()
        assert more.vertices_m[:, 2].max() == pytest.approx(height, rel=1e-9)


def test_the_session_records_the_lean_and_the_cli_checks_it(
    tmp_path: Path, simulate_refuses: SimulateRefuses
) -> None:
    out = tmp_path / "s"
    options = ["--stations", "5", "--views", "0", "--lean", "18"]
    assert main(["simulate", "--out", str(out), *options]) == 0
    assert json.loads((out / "truth.json").read_text())["max_lean_deg"] == 18.0
    plain = tmp_path / "plain"
    assert main(["simulate", "--out", str(plain), "--stations", "5", "--views", "0"]) == 0
    assert "max_lean_deg" not in json.loads((plain / "truth.json").read_text())
    simulate_refuses(
        "--lean",
        [
            ("40", "--lean: 40 is outside 0..30 degrees"),
            ("steep", "--lean: 'steep' is not a number of degrees"),
        ],
    )
    with pytest.raises(ValueError, match="max_lean_deg"):
        make_plant(1, 0, (0.0, 0.0), 0.0, "seedling", "distichous", MAX_LEAN_DEG + 1)
