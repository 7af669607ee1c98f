"""Reconstruct asks before replacing a results folder (Replace / Keep both / Cancel), and the
results panel shows where the results came from."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtWidgets

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.outputs import PlantRow, write_outputs
from ui.results import runner
from ui.results.runner import choose_results_dir, free_results_dir


@pytest.fixture
def earlier(tmp_path: Path) -> Path:
    """A results folder from an earlier run (what the panel and the CLI write first)."""
    folder = tmp_path / "plot-results"
    (folder / "plants").mkdir(parents=True)
    (folder / "plants.csv").write_text("plant,x_m,y_m,height_cm,width_cm,points\n")
    (folder / "plants" / "1.ply").write_bytes(b"earlier")
    return folder


def _answer(monkeypatch: pytest.MonkeyPatch, text: str) -> list[str]:
    """Answer the real question box by clicking its button named ``text``; returns what it
    asked."""
    asked: list[str] = []

    def click(box: QtWidgets.QMessageBox) -> int:
        asked.append(box.text())
        next(b for b in box.buttons() if b.text().replace("&", "") == text).click()
        return 0

    monkeypatch.setattr(QtWidgets.QMessageBox, "exec", click)
    return asked


@pytest.mark.parametrize(
    ("button", "expected"),
    [("Replace", "same"), ("Keep both", "beside"), ("Cancel", None)],
)
def test_each_answer_chooses_a_folder(qtbot, monkeypatch, earlier, button, expected) -> None:
    asked = _answer(monkeypatch, button)
    (earlier.parent / "plot-results-2").mkdir()  # taken: keep both goes to -3
    chosen = choose_results_dir(None, earlier)
    assert asked == [f"{earlier} already holds results. Replace them?"]
    wanted = {"same": earlier, "beside": earlier.parent / "plot-results-3", None: None}
    assert chosen == wanted[expected]


def test_no_question_for_a_new_or_empty_folder(monkeypatch, tmp_path) -> None:
    monkeypatch.setattr(runner, "ask_overwrite", lambda *a: pytest.fail("asked"))
    assert choose_results_dir(None, tmp_path / "new") == tmp_path / "new"
    assert choose_results_dir(None, tmp_path) == tmp_path
    assert free_results_dir(tmp_path / "new") == tmp_path / "new-2"


@pytest.mark.parametrize("answer", ["cancel", "keep both", "replace"])
def test_reconstruct_asks_and_keeps_earlier_results(
    panel,
    plot_session,
    earlier,
    monkeypatch,
    answer,
) -> None:
    started: list[Path] = []
    monkeypatch.setattr(runner, "ask_overwrite", lambda parent, folder, existing: answer)
    monkeypatch.setattr(panel.runner, "start", lambda session, settings, f: started.append(f))
    panel.open_session(plot_session)
    panel.results_dir.setText(str(earlier))
    panel.reconstruct()
    if answer == "cancel":
        assert started == [] and "are kept" in panel.stage.text()
        assert panel.run_button.isEnabled()
    else:
        folder = earlier if answer == "replace" else earlier.parent / "plot-results-2"
        assert started == [folder] and panel.results_dir.text() == str(folder)
    assert (earlier / "plants" / "1.ply").read_bytes() == b"earlier"  # nothing lost yet


def test_the_panel_shows_the_provenance_line(panel, tmp_path) -> None:
    cloud = Cloud(np.zeros((3, 3)), np.zeros((3, 3), np.uint8))
    rows = [PlantRow(1, 0.0, 0.0, 10.0, 5.0, 3)]
    report = {"session": "s", "warnings": []}
    write_outputs(tmp_path / "old", rows, cloud, {1: cloud}, report)
    panel.open_results(tmp_path / "old")
    assert panel.provenance.text().startswith("Provenance unknown")
    document = {
        "source": {"kind": "simulated", "detail": "fieldapp simulate (scene plot, seed 0)"},
        "calibration": {"kind": "nominal", "sha256": "0123456789ab", "file": "/x/c.json"},
        "software": {"version": "0.1.0", "commit": "abcdef012345"},
        "settings_sha256": "a1b2c3d4e5f6",
    }
    write_outputs(tmp_path / "new", rows, cloud, {1: cloud}, report | {"provenance": document})
    assert json.loads((tmp_path / "new" / "provenance.json").read_text()) == document
    panel.open_results(tmp_path / "new")
    assert panel.provenance.text() == (
        "Simulated devices · calibration: nominal (sha256 01234567) · "
        "fieldapp 0.1.0 (abcdef012345) · settings a1b2c3d4"
    )
    tooltip = panel.provenance.toolTip()
    assert "fieldapp simulate (scene plot, seed 0)" in tooltip and "/x/c.json" in tooltip
    assert "settings sha256 a1b2c3d4e5f6" in tooltip
