"""An export of a results folder keeps its organs: the organ columns of plants.csv and
leaves.csv (no widget involved)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.outputs import LeafRow, PlantRow, read_ply, write_outputs
from fieldapp.results.files import read_plants_csv
from ui.results.data import load_results_dir
from ui.results.export import export_results


def test_an_export_keeps_the_organs(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    cloud = Cloud(rng.random((50, 3)), rng.integers(0, 255, (50, 3), dtype=np.uint8))
    rows = [PlantRow(1, 0.5, 0.5, 30.0, 40.0, 50, leaf_count=1, leaf_area_cm2=55.5)]
    leaves = [LeafRow(1, 1, 20.0, 4.0, 55.5, 40.0, 90.0, 5.0)]
    report = {"format": "fieldapp-reconstruction-report/1", "session": "s", "warnings": []}
    source = tmp_path / "source"
    write_outputs(source, rows, cloud, {1: cloud}, report, leaves=leaves)
    exported = tmp_path / "exported"
    export_results(load_results_dir(source), exported)
    assert (exported / "leaves.csv").read_bytes() == (source / "leaves.csv").read_bytes()
    header, line = (exported / "plants.csv").read_text().splitlines()
    assert header.split(",")[6:8] == ["leaf_count", "leaf_area_cm2"]
    assert line.split(",")[6:8] == ["1", "55.50"]
    assert [p.plant for p in read_plants_csv(exported / "plants.csv")] == [1]
    assert len(read_ply(exported / "plants" / "1.ply")) == 50
    assert json.loads((exported / "report.json").read_text())["session"] == "s"


def test_the_leaves_tab_follows_the_selected_plant(qtbot, tmp_path: Path) -> None:
    from fieldapp.settings import Settings
    from ui.results import ResultsPanel

    from .conftest import release_plot_menus

    rng = np.random.default_rng(1)
    cloud = Cloud(rng.random((60, 3)), rng.integers(0, 255, (60, 3), dtype=np.uint8))
    rows = [PlantRow(1, 0.2, 0.2, 30.0, 40.0, 30), PlantRow(2, 0.8, 0.8, 30.0, 40.0, 30)]
    leaves = [LeafRow(1, k, 20.0 + k, 4.0, 55.5, 40.0, 90.0, 5.0 * k) for k in (1, 2, 3)]
    report = {"format": "fieldapp-reconstruction-report/1", "session": "s", "warnings": []}
    write_outputs(tmp_path / "r", rows, cloud, {1: cloud, 2: cloud}, report, leaves=leaves)
    settings = Settings()
    settings.paths.results_db = tmp_path / "results.sqlite"
    panel = ResultsPanel(settings)
    qtbot.addWidget(panel)
    try:
        panel.open_results(tmp_path / "r")
        panel.select_plant(1)
        model = panel.leaves.model()
        assert model.rowCount() == 3
        assert [model.index(r, 1).data() for r in range(3)] == ["21.0", "22.0", "23.0"]
        panel.select_plant(2)
        assert panel.leaves.model().rowCount() == 0
    finally:
        panel.shutdown()
        release_plot_menus(panel)
