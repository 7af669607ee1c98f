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
from fieldapp.evaluate.organs import OrganEvaluation, evaluate_organs
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


def test_leaves_of_leaning_grown_plants_of_the_second_model(tmp_path: Path) -> None:
    """The second plant model: the angles and insertions follow the leaning stems (stem-like
    axis: 39.0 / 31.7 degrees and 1.93 / 1.80 cm). Its long erect leaves are still cut where
    they rise into the upper leaves' bundle (lengths 12-15 cm RMSE), not checked here, and
    where such a leaf is cut decides its angle: one plot's angle RMSE swings with nothing
    that matters (seed 32: 11.2 degrees, 19.7 with the plants' voxel 2.01 mm instead of 2;
    11.2 -> 13.0 and seed 34 9.3 -> 5.2 with the overlaps' soil at its blocks' median depth,
    a tenth of a millimetre of registration). So the angles are judged over both plots
    together (10.3 -> 9.8 degrees), the insertions plot by plot (1.25 / 0.98 -> 1.21 / 1.24
    cm)."""
    evaluations = [evaluated(tmp_path / str(seed), seed, "irregular") for seed in (32, 34)]
    for e in evaluations:
        assert len(e.pairs) == 4
        assert e.by_leaf_trait["insertion_height_cm"].rmse <= 1.5
    both = evaluate_organs([pair for e in evaluations for pair in e.pairs])
    assert both.by_leaf_trait["angle_from_stem_deg"].rmse <= 12.0
