"""Organ traits against a truth and against hand-measured leaves: pairing, figures worked by
hand, bad cells named."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from fieldapp.cli import main
from fieldapp.errors import FormatError
from fieldapp.evaluate.organ_files import read_table
from fieldapp.evaluate.organs import (
    azimuth_difference_deg,
    evaluate_organs,
    pair_leaves,
    pair_plant,
)


def leaf(leaf_id: int, azimuth: float, height: float, length: float = 20.0) -> dict:
    return {
        "leaf_id": leaf_id,
        "length_cm": length,
        "max_width_cm": 4.0,
        "area_cm2": 50.0,
        "angle_from_stem_deg": 40.0,
        "azimuth_deg": azimuth,
        "insertion_height_cm": height,
    }


def test_azimuths_are_compared_on_the_circle() -> None:
    assert azimuth_difference_deg(355.0, 5.0) == pytest.approx(-10.0)
    assert azimuth_difference_deg(5.0, 355.0) == pytest.approx(10.0)
    assert azimuth_difference_deg(90.0, 270.0) == pytest.approx(-180.0)


def test_leaves_are_paired_where_they_leave_the_stem() -> None:
    found = [leaf(1, 358.0, 4.0), leaf(2, 180.0, 6.0), leaf(3, 90.0, 30.0)]
    truth = [leaf(1, 175.0, 6.5), leaf(2, 2.0, 4.2), leaf(3, 0.0, 9.0)]
    assert sorted(pair_leaves(found, truth)) == [(0, 1), (1, 0)]


def test_agreement_of_paired_leaves_and_plants() -> None:
    found = [leaf(1, 350.0, 4.0, 21.0), leaf(2, 170.0, 6.0, 19.0), leaf(3, 90.0, 30.0)]
    truth = [leaf(1, 10.0, 4.5, 20.0), leaf(2, 180.0, 6.5, 20.0)]
    plant = {"leaf_count": 3, "leaf_area_cm2": 150.0, "stem_diameter_mm": 12.0}
    expected = {"leaf_count": 2, "leaf_area_cm2": 100.0, "stem_diameter_mm": 11.0, "leaves": truth}
    other = {"leaf_count": 2, "leaf_area_cm2": 100.0, "stem_diameter_mm": 10.0}
    e = evaluate_organs(
        [
            pair_plant(1, "p01", plant, found, expected),
            pair_plant(2, "p02", other, found[:2], expected),
        ]
    )
    assert e.count_exact == 1 and e.extra == 1 and e.missed == 0
    assert e.by_leaf_trait["length_cm"].n == 4
    assert e.by_leaf_trait["length_cm"].rmse == pytest.approx(1.0)
    assert e.by_leaf_trait["azimuth_deg"].rmse == pytest.approx(math.sqrt((400 + 100) / 2))
    assert e.by_leaf_trait["azimuth_deg"].bias == pytest.approx(-15.0)
    assert e.by_plant_trait["stem_diameter_mm"].rmse == pytest.approx(1.0)
    assert e.by_plant_trait["leaf_area_cm2"].mape_percent == pytest.approx(25.0)


def _results(folder: Path) -> Path:
    folder.mkdir(parents=True)
    (folder / "plants.csv").write_text(
        "plant,x_m,y_m,height_cm,width_cm,points,leaf_count,leaf_area_cm2,stem_diameter_mm\n"
        "1,0.0,0.0,30.0,40.0,900,2,100.0,12.0\n"
        "2,0.8,0.0,32.0,44.0,950,1,60.0,\n",
        encoding="utf-8",
    )
    (folder / "leaves.csv").write_text(
        "plant_id,leaf_id,length_cm,max_width_cm,area_cm2,angle_from_stem_deg,azimuth_deg,"
        "insertion_height_cm\n"
        "1,1,21.00,4.00,50.00,40.00,10.00,4.00\n"
        "1,2,19.00,4.00,50.00,40.00,190.00,6.00\n"
        "2,1,20.00,4.00,60.00,40.00,90.00,5.00\n",
        encoding="utf-8",
    )
    return folder


def test_cli_against_a_truth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    results = _results(tmp_path / "out")
    plants = [
        {
            "name": "p01",
            "x_m": 0.01,
            "y_m": 0.0,
            "height_cm": 30,
            "width_cm": 40,
            "leaf_count": 2,
            "leaf_area_cm2": 100.0,
            "stem_diameter_mm": 11.0,
            "leaves": [leaf(1, 0.0, 4.0), leaf(2, 180.0, 6.0)],
        },
        {
            "name": "p02",
            "x_m": 0.8,
            "y_m": 0.01,
            "height_cm": 32,
            "width_cm": 44,
            "leaf_count": 2,
            "leaf_area_cm2": 110.0,
            "stem_diameter_mm": 12.0,
            "leaves": [leaf(1, 90.0, 5.0), leaf(2, 270.0, 8.0)],
        },
    ]
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"format": "fieldapp-sim-truth/1", "plants": plants}))
    assert main(["evaluate", "organs", str(results), "--truth", str(truth)]) == 0
    out = capsys.readouterr().out
    assert "leaf count exact on 1 of 2 plants; 0 leaves found but not in the reference, 1" in out
    assert "length_cm: n = 3, R2 = n/a, RMSE = 0.816" in out
    assert "azimuth_deg: n = 3" in out and "bias = 6.667" in out
    metrics = (results / "evaluation" / "organs_metrics.csv").read_text().splitlines()
    assert metrics[0].startswith("trait,level,n,r2,rmse")
    assert (
        "stem_diameter_mm,plant,1," in (results / "evaluation" / "organs_metrics.csv").read_text()
    )
    assert len((results / "evaluation" / "leaf_pairs.csv").read_text().splitlines()) == 4


def test_cli_against_hand_measured_leaves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    results = _results(tmp_path / "out")
    manual = tmp_path / "leaves_manual.csv"
    manual.write_text("plant_id,leaf_id,length_cm,area_cm2\n1,1,20,48\n1,2,20,\n2,1,22,60\n")
    assert main(["evaluate", "organs", str(results), "--manual-leaves", str(manual)]) == 0
    out = capsys.readouterr().out
    assert "leaf count exact on 2 of 2 plants" in out
    assert "length_cm: n = 3, R2 = " in out and f"RMSE = {math.sqrt(6 / 3):.3f}, " in out
    assert "leaf_area_cm2: n = 1," in out  # plant 1's second leaf has no area measured


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("plant_id,leaf_id\n1,x\n", "row 2 column leaf_id: 'x' is not a number"),
        ("plant_id,leaf_id\n1.5,1\n", "row 2 column plant_id: '1.5' is not a whole number"),
        ("plant_id,leaf_id,length_cm\n1,1,inf\n", "row 2 column length_cm: not a finite"),
        ("plant_id,length_cm\n1,2\n", "header: missing column(s) leaf_id"),
    ],
)
def test_bad_leaf_cells_are_named(tmp_path: Path, text: str, where: str) -> None:
    path = tmp_path / "leaves.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(FormatError) as error:
        read_table(path, ("plant_id", "leaf_id"))
    assert where in str(error.value) and str(path) in str(error.value)


def test_the_html_report_lists_plants_organs_and_leaves(tmp_path: Path) -> None:
    from fieldapp.evaluate.report import organs_section

    results = _results(tmp_path / "out")
    text = organs_section(results)
    assert text.count("<tr>") == 1 + 2 + 1 + 3  # plants header + 2, leaves header + 3
    assert "<td>19.00</td>" in text and "3 leaves" in text
    (results / "leaves.csv").unlink()
    assert "not measured" in organs_section(results)


def test_the_report_shows_the_organ_accuracy(tmp_path: Path) -> None:
    from fieldapp.evaluate.organ_files import evaluate_organ_references
    from fieldapp.evaluate.report import organ_evaluation_section

    results = _results(tmp_path / "out")
    manual = tmp_path / "leaves_manual.csv"
    manual.write_text("plant_id,leaf_id,length_cm,area_cm2\n1,1,20,48\n1,2,20,\n2,1,22,60\n")
    evaluation, warnings = evaluate_organ_references(results, manual_leaves=manual)
    assert warnings == [] and evaluation.by_leaf_trait["length_cm"].n == 3
    text = organ_evaluation_section(evaluation)
    assert "Leaf count exact on 2 of 2 plants; 0 leaves found but not in the reference; 0" in text
    assert text.count("<tr>") == 1 + 9  # header, every leaf and plant trait
    assert "<td>length_cm</td><td>leaf</td><td>cm</td><td>3</td>" in text
    assert f"<td>{math.sqrt(6 / 3):.2f}</td>" in text  # the length's RMSE, as the CLI's
    # a scatter for each trait compared: the leaves' length and area, the count and area
    assert text.count("data:image/png;base64") == 4
    assert organ_evaluation_section(None) == ""


def test_fieldapp_report_adds_the_organ_accuracy(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    results = _results(tmp_path / "out")
    (results / "report.json").write_text('{"session": "s", "warnings": []}')
    manual = tmp_path / "leaves_manual.csv"
    manual.write_text("plant_id,leaf_id,length_cm\n1,1,20\n3,1,20\n")
    out = tmp_path / "report.html"
    assert main(["report", str(results), "--out", str(out), "--manual-leaves", str(manual)]) == 0
    text = out.read_text()
    assert "Organ accuracy against the reference" in text
    assert "plant 3 of" in text  # a plant measured by hand but not found is a warning
    (results / "leaves.csv").unlink()
    assert main(["report", str(results), "--out", str(out), "--manual-leaves", str(manual)]) == 1
    assert f"{results / 'leaves.csv'}: file is missing" in capsys.readouterr().err


def test_one_reference_exactly(tmp_path: Path) -> None:
    from fieldapp.errors import FieldappError
    from fieldapp.evaluate.organ_files import evaluate_organ_references

    results = _results(tmp_path / "out")
    with pytest.raises(FieldappError, match=r"either a truth\.json or a file"):
        evaluate_organ_references(results)
    with pytest.raises(FieldappError, match=r"either a truth\.json or a file"):
        evaluate_organ_references(results, tmp_path / "t.json", tmp_path / "m.csv")
