"""``simulate --station-spacing``: the stations nearer together (or farther apart) than the
paper's 1.6 m, the plot's plants where the default plan has them.

A mission may set its stations closer (more views of each plant, a lower camera) on the same
plot: the outer plants then stand farther beyond the outer stations, and a crop scaled down
with the spacing cut their outer leaves (``backproject.rig_crop``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fieldapp.cli import main


def _simulate(folder: Path, *options: str) -> dict:
    common = ["--grid", "2", "--views", "0", "--seed", "3"]
    assert main(["simulate", "--out", str(folder), *common, *options]) == 0
    return json.loads((folder / "truth.json").read_text())


def test_the_stations_move_and_the_plants_stay(tmp_path: Path) -> None:
    paper = _simulate(tmp_path / "paper")
    near = _simulate(tmp_path / "near", "--station-spacing", "1.2")
    assert near["station_spacing_m"] == 1.2 and "station_spacing_m" not in paper
    for truth, spacing in ((paper, 1.6), (near, 1.2)):
        cameras = {int(s): np.array(T)[:2, 3] for s, T in truth["T_field_camera"].items()}
        # every camera turns on its own table: the cameras of stations 1 and 2 (one row) are
        # the stations' spacing apart, to the base's arrival error
        assert np.linalg.norm(cameras[2] - cameras[1]) == pytest.approx(spacing, abs=0.05)
    assert [p["x_m"] for p in near["plants"]] == [p["x_m"] for p in paper["plants"]]
    assert [p["width_cm"] for p in near["plants"]] == [p["width_cm"] for p in paper["plants"]]
    plan = json.loads((tmp_path / "near" / "session.json").read_text())["plan"]
    grid, paper_plan = (
        plan["planting_grid"],
        json.loads((tmp_path / "paper" / "session.json").read_text())["plan"],
    )
    # the planting grid in the map frame (station 1 at its origin): the stations span 0.4 m
    # less round the same plants, so station 1 stands 0.2 m nearer the first plant
    assert grid["plant_spacing_m"] == paper_plan["planting_grid"]["plant_spacing_m"]
    assert grid["origin"]["x"] == pytest.approx(paper_plan["planting_grid"]["origin"]["x"] - 0.2)


def test_a_spacing_out_of_range_or_for_a_scene_without_stations_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["simulate", "--out", str(tmp_path / "a"), "--station-spacing", "3"]) != 0
    assert "--station-spacing: 3 is outside 0.6..2.4 metres" in capsys.readouterr().err
    bad = ["--scene", "checkerboard", "--station-spacing", "1.2"]
    assert main(["simulate", "--out", str(tmp_path / "b"), *bad]) != 0
    assert "--station-spacing" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
