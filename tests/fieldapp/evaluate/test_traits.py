"""Traits against hand measurements and against a simulator's truth; bad rows named."""

from __future__ import annotations

import json
import math

import pytest

from fieldapp.cli import main
from fieldapp.errors import FormatError
from fieldapp.evaluate.references import load_truth, pair_with_truth
from fieldapp.results.files import read_manual_csv, read_plants_csv

from ..results.helpers import write_results

ROWS = [(1, 0.0, 0.0, 10.0, 20.0), (2, 0.8, 0.0, 12.0, 24.0), (3, 1.6, 0.0, 15.0, 30.0)]


def test_cli_with_manual_matches_hand_worked_figures(tmp_path, capsys):
    results = write_results(tmp_path / "out", "s", [*ROWS, (4, 2.4, 0.0, 9.0, 9.0)])
    manual = tmp_path / "manual.csv"
    manual.write_text(
        "plant,height_cm,width_cm\n1,11,20\n2,12,\n3,13,30\n7,5,5\n", encoding="utf-8"
    )
    assert main(["evaluate", "traits", str(results), "--manual", str(manual)]) == 0
    out = capsys.readouterr().out
    assert f"height: n = 3, R2 = {75 / 76:.4f}, RMSE = {math.sqrt(5 / 3):.2f} cm" in out
    assert "width: n = 2, R2 = n/a, RMSE = 0.00 cm" in out
    assert "1 plants without a reference: 4" in out
    assert "1 references without a plant: 7" in out
    folder = results / "evaluation"
    for name in ("height_scatter.png", "width_scatter.png"):
        assert (folder / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    metrics = (folder / "traits_metrics.csv").read_text(encoding="utf-8").splitlines()
    assert metrics[1].startswith(f"height,3,{75 / 76:.4f},{math.sqrt(5 / 3):.3f}")


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("plant,height_cm,width_cm\n1,abc,2\n", "row 2 column height_cm: 'abc' is not a number"),
        ("plant,height_cm,width_cm\n1,2,3\n1.5,2,3\n", "row 3 column plant"),
        ("plant,height_cm,width_cm\n1,2,3\n\n1,4,5\n", "row 4 column plant: plant 1 is already"),
        ("plant,height_cm,width_cm\n1,-2,3\n", "row 2 column height_cm: '-2' is negative"),
        ("plant,height_cm,width_cm\n1,nan,3\n", "row 2 column height_cm: 'nan' is not a finite"),
        ("plant,height\n1,2\n", "header: missing column(s) height_cm, width_cm"),
        ("plant,height_cm,width_cm\n", "no measurements"),
    ],
)
def test_bad_manual_rows_are_named(tmp_path, text, where):
    path = tmp_path / "manual.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(FormatError) as error:
        read_manual_csv(path)
    assert where in str(error.value)
    assert str(path) in str(error.value)


def test_cli_reports_bad_input_without_traceback(tmp_path, capsys):
    results = write_results(tmp_path / "out", "s", ROWS)
    manual = tmp_path / "manual.csv"
    manual.write_text("plant,height_cm,width_cm\nx,1,2\n", encoding="utf-8")
    assert main(["evaluate", "traits", str(results), "--manual", str(manual)]) == 1
    assert "row 2 column plant: 'x' is not a whole number" in capsys.readouterr().err
    assert main(["evaluate", "traits", str(tmp_path / "none"), "--manual", str(manual)]) == 1
    assert "plants.csv: file is missing" in capsys.readouterr().err


def test_truth_pairs_by_position(tmp_path, capsys):
    truth = {
        "format": "fieldapp-sim-truth/1",
        "plants": [
            {"name": "p01", "x_m": 0.03, "y_m": -0.02, "z_m": 0.0, "height_cm": 11, "width_cm": 21},
            {"name": "p02", "x_m": 1.62, "y_m": 0.01, "z_m": 0.0, "height_cm": 14, "width_cm": 29},
            {"name": "p03", "x_m": 0.85, "y_m": 0.3, "z_m": 0.0, "height_cm": 1, "width_cm": 1},
        ],
        "spheres": [],
    }
    path = tmp_path / "truth.json"
    path.write_text(json.dumps(truth), encoding="utf-8")
    results = write_results(tmp_path / "out", "s", ROWS)
    pairing = pair_with_truth(
        read_plants_csv(results / "plants.csv"), load_truth(path).plants, 0.15
    )
    assert [(p.plant, p.reference) for p in pairing.pairs] == [(1, "p01"), (3, "p02")]
    assert pairing.pairs[0].distance_m == pytest.approx(math.hypot(0.03, 0.02))
    assert pairing.unmatched_plants == [2] and pairing.unmatched_references == ["p03"]
    assert main(["evaluate", "traits", str(results), "--truth", str(path)]) == 0
    assert "height: n = 2, R2 = n/a, RMSE = 1.00 cm" in capsys.readouterr().out


def test_bad_truth_is_named(tmp_path):
    path = tmp_path / "truth.json"
    path.write_text(json.dumps({"format": "fieldapp-sim-truth/1", "plants": [{"name": "a"}]}))
    with pytest.raises(FormatError, match=r"plants\[0\]\.x_m"):
        load_truth(path)
