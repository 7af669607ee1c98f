"""The results panel on a small simulated session: run, cancel, display, selection, manual
measurements, export; and its refusals of bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fieldapp.errors import FieldappError
from fieldapp.recon.progress import STAGES
from fieldapp.results.files import ManualRecord, read_plants_csv
from ui.results.data import load_results_dir


def _run(panel, plot_session, out):
    stages = []
    panel.runner.progressed.connect(lambda event: stages.append(event.stage))
    panel.open_session(plot_session)
    panel.results_dir.setText(str(out))
    panel.reconstruct()
    assert panel.cancel_button.isEnabled() and not panel.run_button.isEnabled()
    assert panel.runner.wait(90)
    return stages


def test_run_shows_every_plant_against_the_truth(panel, plot_session, tmp_path):
    stages = _run(panel, plot_session, tmp_path / "out")
    assert list(dict.fromkeys(stages)) == list(STAGES)
    assert panel.progress.value() == 1000 and panel.stage.text().startswith("done")
    assert panel.provenance.text().startswith("Simulated devices · calibration: nominal")
    results = panel.results
    assert results is not None and len(results.plants) >= 5
    _same_plants(read_plants_csv(tmp_path / "out" / "plants.csv"), results.plants)
    truth = json.loads((plot_session / "truth.json").read_text())
    truth_xy = np.array([[p["map_x_m"], p["map_y_m"]] for p in truth["plants"]])
    for plant in results.plants:  # every plant found stands where a true plant stands
        assert np.min(np.linalg.norm(truth_xy - [plant.x_m, plant.y_m], axis=1)) < 0.05
    assert panel.plant_model.rowCount() == len(results.plants)
    assert panel.stations.model().rowCount() == 2
    assert panel.warnings.count() == max(1, len(results.warnings))
    labels = panel.view3d.scene.labels
    assert [label.plant for label in labels] == [p.plant for p in results.plants]
    for label, plant in zip(labels, results.plants, strict=True):
        assert label.position_m[:2] == pytest.approx([plant.x_m, plant.y_m])
        top_m = results.plant_clouds[plant.plant].points[:, 2].max()
        assert label.position_m[2] == pytest.approx(top_m)  # the id floats at the plant's top


def test_selection_goes_table_to_views_and_back(panel, plot_session, tmp_path):
    _run(panel, plot_session, tmp_path / "out")
    plants = panel.results.plants
    panel.table.selectRow(2)
    chosen = panel.plant_model.plants[panel.proxy.mapToSource(panel.proxy.index(2, 0)).row()]
    assert panel.view3d.selected == chosen.plant == panel.map.selected
    other = plants[-1].plant
    panel.map.plant_clicked.emit(other)
    assert panel.selected == other == panel.view3d.selected
    row = panel.table.selectionModel().selectedRows()[0]
    assert panel.proxy.data(row) == str(other)
    colors = panel.view3d.scene.colors_for(other)
    mine = panel.view3d.scene.plant_of_point == other
    assert mine.any() and colors[~mine, :3].max() <= 0.35 + 1e-6


def test_cancel_stops_at_a_step_boundary(panel, plot_session, tmp_path, qtbot):
    cancelled = []
    panel.runner.cancelled.connect(lambda: cancelled.append(True))
    panel.runner.progressed.connect(lambda _: panel.cancel())
    panel.open_session(plot_session)
    panel.results_dir.setText(str(tmp_path / "out"))
    panel.reconstruct()
    assert panel.runner.wait(60)
    assert cancelled == [True]
    assert panel.results is None and panel.stage.text() == "cancelled"
    assert not (tmp_path / "out" / "plants.csv").exists()
    assert panel.run_button.isEnabled() and not panel.cancel_button.isEnabled()


def test_manual_values_give_the_accuracy_figures(panel, plot_session, tmp_path):
    _run(panel, plot_session, tmp_path / "out")
    plants = panel.results.plants
    manual = [ManualRecord(p.plant, p.height_cm + 1.0, p.width_cm * 0.9) for p in plants]
    csv = tmp_path / "manual.csv"
    csv.write_text(
        "plant,height_cm,width_cm\n"
        + "".join(f"{m.plant},{m.height_cm},{m.width_cm}\n" for m in manual)
    )
    panel.manual.import_csv(csv)
    evaluation = panel.manual.evaluation
    height, width = evaluation.by_trait["height"], evaluation.by_trait["width"]
    assert height.n == len(plants) and height.rmse == pytest.approx(1.0, abs=1e-6)
    assert height.bias == pytest.approx(-1.0, abs=1e-6)
    # algorithm = manual / 0.9: |a - m| / m = 1 / 0.9 - 1 (the CSV rounds the manual values)
    assert width.mape_percent == pytest.approx(100 * (1 / 0.9 - 1), rel=1e-4)
    assert "RMSE = 1.00 cm" in panel.manual.status.text()
    panel.manual.table.item(0, 2).setText("tall")
    assert "not a number" in panel.manual.status.text()


def test_export_writes_every_file_and_reopens(panel, plot_session, tmp_path):
    _run(panel, plot_session, tmp_path / "out")
    paths = panel.export_to(tmp_path / "export")
    names = {p.relative_to(tmp_path / "export").as_posix() for p in paths}
    assert {
        "traits.csv",
        "cloud.ply",
        "report.html",
        "figures/map.png",
        "figures/traits.png",
    } <= names
    assert all(f"plants/{p.plant}.ply" in names for p in panel.results.plants)
    html = (tmp_path / "export" / "report.html").read_text()
    assert "data:image/png;base64" in html and panel.results.session_id in html
    again = load_results_dir(tmp_path / "export")
    _same_plants(again.plants, panel.results.plants)
    assert len(again.cloud) == len(panel.results.cloud)


def test_bad_inputs_are_clear_errors(panel, tmp_path):
    with pytest.raises(FieldappError, match="open a session first"):
        panel.reconstruct()
    with pytest.raises(FieldappError, match="no such folder"):
        panel.open_session(tmp_path / "nowhere")
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "plants.csv").write_text("plant,x_m\n1,2\n")
    with pytest.raises(FieldappError, match="missing column"):
        panel.open_results(tmp_path / "broken")


def test_history_records_runs_and_draws_growth(panel, plot_session, tmp_path):
    _run(panel, plot_session, tmp_path / "out")
    panel.history.plot_name.setText("plot-A")
    panel.history.record("plot-A", plot_session, tmp_path / "out")
    assert "✓ Recorded" in panel.history.status.text()  # a visible confirmation
    assert "on 1 date (" in panel.history.status.text()
    observations = panel.history.load("plot-A")
    assert len(observations) == len(panel.results.plants)
    series = panel.history.series()
    assert sorted(series) == sorted(o.plant_number for o in observations)
    first = observations[0]
    assert series[first.plant_number][0][1] == pytest.approx(first.height_cm)


def _same_plants(written, shown):
    """The CSV rounds to 0.1 mm and 0.1 mm of trait."""
    assert [p.plant for p in written] == [p.plant for p in shown]
    for a, b in zip(written, shown, strict=True):
        assert (a.x_m, a.y_m) == pytest.approx((b.x_m, b.y_m), abs=1e-4)
        assert (a.height_cm, a.width_cm) == pytest.approx((b.height_cm, b.width_cm), abs=0.01)
        assert a.points == b.points
