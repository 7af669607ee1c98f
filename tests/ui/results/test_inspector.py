"""The per-plant inspector and the organ accuracy in the results panel, on the session-scoped
simulated plot reconstructed once for this module (about 2.5 s of CPU)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from fieldapp.cli import main
from fieldapp.evaluate.organ_files import evaluate_organ_references
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.organs import ORGAN_LEAF, ORGAN_STEM
from fieldapp.recon.outputs import PointLabels, ply_bytes, read_labelled_ply
from fieldapp.results.organ_tables import read_table
from ui.results.data import load_results_dir
from ui.results.plant_drawing import DIM, STEM_RGB, leaf_rgb, plant_drawing


@pytest.fixture(scope="module")
def plot_results(plot_session: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("inspector") / "results"
    assert main(["reconstruct", str(plot_session), "--out", str(out), "--quiet"]) == 0
    return out


def test_each_plant_is_drawn_with_its_organs_height_and_width(plot_results: Path) -> None:
    results = load_results_dir(plot_results)
    leaves = read_table(plot_results / "leaves.csv", ("plant_id", "leaf_id"))
    assert len(results.plants) >= 5
    for record in results.plants:
        d = plant_drawing(results, record.plant)
        assert len(d.points_m) == record.points
        # the circle drawn is the one measured: its diameter is plants.csv's width
        centre = d.width_circle_m[:-1].mean(axis=0)
        radii = np.linalg.norm(d.width_circle_m[:, :2] - centre[:2], axis=1)
        assert 200 * radii == pytest.approx(record.width_cm, abs=0.01)
        inside = np.linalg.norm(d.points_m[:, :2] - centre[:2], axis=1) <= radii[0] + 1e-4
        assert inside.all()
        # the height line stands at the foot, from the local ground (near the fitted ground,
        # z = 0) up to one of the plant's points
        line = d.height_line_m
        assert line[0, :2] == pytest.approx([record.x_m, record.y_m])
        assert 100 * (line[1, 2] - line[0, 2]) == pytest.approx(record.height_cm)
        assert abs(line[0, 2]) < 0.05 and np.isclose(d.points_m[:, 2], line[1, 2]).any()
        assert [row["leaf_id"] for row in d.leaves] == [
            row["leaf_id"] for row in leaves if row["plant_id"] == record.plant
        ]
        stem = d.organ == ORGAN_STEM
        assert stem.any() and np.allclose(d.colors[stem, :3], STEM_RGB)
        for leaf_id in np.unique(d.leaf_id[d.organ == ORGAN_LEAF]):
            mine = d.leaf_id == leaf_id
            assert np.allclose(d.colors[mine, :3], leaf_rgb(int(leaf_id)))
    assert len({leaf_rgb(k) for k in range(1, 9)}) == 8  # each leaf its own colour


def test_results_opened_without_their_session_say_whose_they_are(panel, plot_results: Path) -> None:
    assert panel.session is None and panel.session_label.text() == "No session open."
    panel.open_results(plot_results)
    assert panel.session_label.text() == (
        f"results of session {panel.results.session_id} (its session is not open: open it to "
        "reconstruct again)"
    )


def test_the_plant_table_pane_is_as_wide_as_its_columns(panel, qtbot, plot_results: Path) -> None:
    """Its last column, "found", carries each plant's flag: it used to start past the pane's
    edge, the flags a scroll away."""
    panel.resize(1500, 900)
    panel.show()
    qtbot.waitExposed(panel)
    panel.open_results(plot_results)
    header = panel.table.horizontalHeader()
    table_pane, rest = panel.splitter.sizes()
    assert table_pane >= min(header.length(), (table_pane + rest) // 2)
    assert header.sectionViewportPosition(header.count() - 1) < panel.table.viewport().width()


def test_the_inspector_follows_and_drives_the_selection(panel, plot_results: Path) -> None:
    panel.open_results(plot_results)
    plants = [p.plant for p in panel.results.plants]
    inspector = panel.inspector
    assert inspector.drawing is None and inspector.plants.count() == len(plants) + 1
    panel.table.selectRow(1)  # the plant table -> the inspector
    chosen = panel.selected
    assert inspector.drawing.plant == chosen
    assert "each within 8 mm of the next, leads 2 cm down" in inspector.caption.text()
    assert "smallest circle" in inspector.caption.text()
    panel.map.plant_clicked.emit(plants[-1])  # the map -> the inspector
    assert inspector.drawing.plant == plants[-1] == inspector.plants.currentData()
    inspector.plants.setCurrentIndex(inspector.plants.findData(plants[0]))  # and back
    assert panel.selected == plants[0] == panel.view3d.selected == panel.map.selected
    row = panel.table.selectionModel().selectedRows()[0]
    assert panel.proxy.data(row) == str(plants[0])
    assert inspector.drawing.plant == plants[0]


def test_a_leaf_row_highlights_that_leaf(panel, plot_results: Path) -> None:
    panel.open_results(plot_results)
    plant = max(panel.results.plants, key=lambda p: len(panel.results.leaves.get(p.plant, [])))
    panel.select_plant(plant.plant)
    inspector = panel.inspector
    model = inspector.leaves.model()
    assert model.rowCount() == len(panel.results.leaves[plant.plant]) >= 2
    inspector.leaves.selectRow(1)
    leaf_id = int(model.index(1, 0).data())
    assert inspector.highlighted_leaf == leaf_id
    drawing = inspector.drawing
    for (organ, leaf), item in inspector.view.groups.items():
        rgb = np.array(item.opts["brush"].color().getRgbF()[:3])
        full = drawing.colors[(drawing.organ == organ) & (drawing.leaf_id == leaf)][0, :3]
        expected = full if leaf == leaf_id else DIM * full
        assert rgb == pytest.approx(expected, abs=1 / 255)
    for (organ, leaf), item in inspector.view.groups.items():  # drawn across the leaves
        mine = drawing.points_m[(drawing.organ == organ) & (drawing.leaf_id == leaf)]
        assert item.data["x"] == pytest.approx(drawing.along_fan_m(mine), abs=1e-6)
    inspector.select_leaf(None)
    assert inspector.leaves.selectionModel().selectedRows() == []


def test_the_view_looks_across_the_leaves() -> None:
    from ui.results.plant_drawing import fan_direction

    rng = np.random.default_rng(3)
    for angle_deg in (0.0, 30.0, 115.0):
        along = rng.uniform(-0.2, 0.2, 500)
        across = rng.normal(0.0, 0.01, 500)
        a = np.radians(angle_deg)
        xy = np.c_[along * np.cos(a) - across * np.sin(a), along * np.sin(a) + across * np.cos(a)]
        direction = fan_direction(xy + np.array([1.0, 2.0]))
        assert abs(direction @ [np.cos(a), np.sin(a)]) == pytest.approx(1.0, abs=1e-3)


def test_organ_accuracy_against_the_truth_and_in_the_export(
    panel, plot_session: Path, plot_results: Path, tmp_path: Path
) -> None:
    results = load_results_dir(plot_results)
    results.session_folder = plot_session  # as after a reconstruction in the panel
    panel.show_results(results)
    shown = panel.organ_accuracy.evaluation
    expected, _ = evaluate_organ_references(plot_results, truth=plot_session / "truth.json")
    assert shown is not None and shown.by_leaf_trait == expected.by_leaf_trait
    assert shown.by_plant_trait == expected.by_plant_trait
    table = panel.organ_accuracy.table
    assert table.rowCount() == 9 and table.item(0, 0).text() == "length_cm (cm)"
    assert table.item(0, 2).text() == str(expected.by_leaf_trait["length_cm"].n)
    status = panel.organ_accuracy.status.text()
    assert f"leaf count exact on {expected.count_exact} of {len(expected.pairs)} plants" in status
    assert f"{expected.extra} leaves found but not in the reference" in status
    assert f"{expected.missed} reference leaves not found" in status
    job = panel.export_job(tmp_path / "export")
    assert job.keywords["organ_evaluation"] is shown


def test_a_bad_truth_is_named_not_raised(panel, plot_results: Path, tmp_path: Path) -> None:
    (tmp_path / "truth.json").write_text('{"format": "fieldapp-sim-truth/1", "plants": [{}]}')
    results = load_results_dir(plot_results)
    results.session_folder = tmp_path
    panel.show_results(results)
    assert panel.organ_accuracy.evaluation is None
    assert panel.organ_accuracy.status.text().startswith("⚠")
    assert str(tmp_path / "truth.json") in panel.organ_accuracy.status.text()


def test_organ_accuracy_against_hand_measured_leaves(panel, plot_results: Path, tmp_path) -> None:
    from fieldapp.errors import FieldappError

    panel.open_results(plot_results)
    accuracy = panel.organ_accuracy
    assert accuracy.evaluation is None and accuracy.manual_button.isEnabled()
    leaves = read_table(plot_results / "leaves.csv", ("plant_id", "leaf_id"))[:6]
    manual = tmp_path / "manual_leaves.csv"
    manual.write_text(
        "plant_id,leaf_id,length_cm\n"
        + "".join(f"{r['plant_id']},{r['leaf_id']},{r['length_cm'] + 1.0}\n" for r in leaves)
        + "999,1,20\n"
    )
    accuracy.compare(manual_leaves=manual)
    length = accuracy.evaluation.by_leaf_trait["length_cm"]
    assert length.n == 6 and length.bias == pytest.approx(-1.0, abs=1e-6)
    assert "plant 999 of" in accuracy.status.text()
    manual.write_text("plant_id,leaf_id,length_cm\n1,x,3\n")
    with pytest.raises(FieldappError, match="column leaf_id"):
        accuracy.compare(manual_leaves=manual)


def test_an_export_carries_the_organ_accuracy(tmp_path: Path) -> None:
    from fieldapp.recon.cloud import Cloud
    from fieldapp.recon.outputs import LeafRow, PlantRow, write_outputs
    from ui.results.export import export_results

    rng = np.random.default_rng(2)
    cloud = Cloud(rng.random((40, 3)), rng.integers(0, 255, (40, 3), dtype=np.uint8))
    rows = [PlantRow(1, 0.5, 0.5, 30.0, 40.0, 40, leaf_count=2, leaf_area_cm2=100.0)]
    leaves = [LeafRow(1, k, 20.0 + k, 4.0, 50.0, 40.0, 90.0, 5.0 * k) for k in (1, 2)]
    report = {"format": "fieldapp-reconstruction-report/1", "session": "s", "warnings": []}
    write_outputs(tmp_path / "r", rows, cloud, {1: cloud}, report, leaves=leaves)
    manual = tmp_path / "manual_leaves.csv"
    manual.write_text("plant_id,leaf_id,length_cm\n1,1,20\n1,2,21\n")
    evaluation, _ = evaluate_organ_references(tmp_path / "r", manual_leaves=manual)
    written = export_results(
        load_results_dir(tmp_path / "r"), tmp_path / "e", organ_evaluation=evaluation
    )
    assert {tmp_path / "e" / "organs_metrics.csv", tmp_path / "e" / "leaf_pairs.csv"} <= set(
        written
    )
    metrics = (tmp_path / "e" / "organs_metrics.csv").read_text()
    assert "length_cm,leaf,2,,1.000," in metrics  # both leaves 1 cm longer than by hand
    html = (tmp_path / "e" / "report.html").read_text()
    assert "Organ accuracy against the reference" in html
    assert "Leaf count exact on 1 of 1 plants" in html


def test_the_circle_drawn_leaves_out_the_mixed_points_as_the_width_does(
    plot_results: Path, tmp_path: Path
) -> None:
    """A plant file whose points carry mixed flags (a session with black pixels): a veil
    point far off the plant is drawn, but the circle is plants.csv's width."""
    folder = Path(shutil.copytree(plot_results, tmp_path / "results"))
    record = load_results_dir(folder).plants[0]
    path = folder / "plants" / f"{record.plant}.ply"
    cloud, labels = read_labelled_ply(path)
    assert labels is not None
    veil = cloud.points.mean(axis=0) + np.array([[0.5, 0.0, 0.0]])
    one = np.ones(1, np.uint8)
    flagged = Cloud(
        np.concatenate([cloud.points, veil]),
        np.concatenate([cloud.colors, np.zeros((1, 3), np.uint8)]),
        np.concatenate([np.zeros(len(cloud), bool), [True]]),
    )
    more = PointLabels(
        np.concatenate([labels.plant_id, [record.plant]]).astype(np.int32),
        np.concatenate([labels.organ, 0 * one]),
        np.concatenate([labels.leaf_id, 0 * one]),
    )
    path.write_bytes(ply_bytes(flagged, more))
    d = plant_drawing(load_results_dir(folder), record.plant)
    assert len(d.points_m) == len(cloud) + 1
    centre = d.width_circle_m[:-1].mean(axis=0)
    radii = np.linalg.norm(d.width_circle_m[:, :2] - centre[:2], axis=1)
    assert 200 * radii == pytest.approx(record.width_cm, abs=0.01)
