"""Hard cases for the registration: G x G station grids, set arrival errors, bare soil."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.sim.rig import RigGeometry, StopErrors
from devices.sim.scene import PlotLayout, bare_soil_scene, soil_for_plot
from fieldapp.cli import main
from fieldapp.io.session import load_session


@pytest.mark.parametrize("grid", [3, 5, 9])
def test_a_grid_of_stations_is_centred_on_the_field_origin(grid: int) -> None:
    rig = RigGeometry(grid=grid)
    assert rig.stations == tuple(range(1, grid * grid + 1))
    reference = rig.T_field_base(rig.station_pose(rig.reference_station))
    assert reference[:2, 3] == pytest.approx([0.0, 0.0])
    first = rig.T_field_base(rig.station_pose(1))[:2, 3]
    last = rig.T_field_base(rig.station_pose(grid * grid))[:2, 3]
    assert first == pytest.approx([-rig.plot_half_extent_m] * 2)
    assert last == pytest.approx([rig.plot_half_extent_m] * 2)
    assert soil_for_plot(rig.plot_half_extent_m).half_extent_m >= rig.plot_half_extent_m + 2.5
    with pytest.raises(ValueError, match=rf"1\.\.{grid * grid}"):
        rig.station_pose(grid * grid + 1)


def test_plants_spread_over_the_whole_plot() -> None:
    layout = PlotLayout.for_stations(7, 1.6)
    positions = layout.positions(np.random.default_rng(0))
    assert len(positions) == 144  # 12 x 12, as on the 7 x 7 plot of the issue
    assert np.abs(positions).max() == pytest.approx(4.4, abs=0.05)
    assert PlotLayout.for_stations(3, 1.6) == PlotLayout()  # the standard 4 x 4 plot


def test_arrival_errors_have_the_set_spread() -> None:
    errors = StopErrors.arrival(0.1, 5.0)
    goal = RigGeometry().station_pose(5)
    rng = np.random.default_rng(0)
    true = [errors.base_stop(goal, rng)[1] for _ in range(4000)]
    dx = np.array([p.x_m - goal.x_m for p in true])
    dyaw = np.array([p.yaw_deg - goal.yaw_deg for p in true])
    assert np.std(dx) == pytest.approx(0.1, rel=0.08)
    assert np.std(dyaw) == pytest.approx(5.0, rel=0.08)


def test_a_poorly_localised_base_reports_stops_off_by_the_localisation_error(
    tmp_path: Path,
) -> None:
    out = tmp_path / "lost"
    options = ["--stations", "1-9", "--views", "0", "--localisation-error", "0.2,8"]
    assert main(["simulate", "--out", str(out), *options]) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["localisation_error"] == {"sigma_m": 0.2, "sigma_deg": 8.0}
    session = load_session(out)
    reported = {c.station: c.base_pose for c in session.captures}
    off = []
    for station, entry in truth["stations"].items():
        pose = reported[int(station)]
        assert pose is not None
        true = entry["true_pose"]
        off.append(np.hypot(pose.x - true["x"], pose.y - true["y"]))
    assert 0.1 < max(off) < 0.6  # far more than the default's 1.5 cm, within 3 sigma


def test_bare_soil_has_nothing_but_soil() -> None:
    scene = bare_soil_scene(0)
    assert [body.kind for body in scene.bodies] == ["soil"]
    assert not scene.plants and not scene.spheres


def test_a_5x5_session_has_its_stations_and_their_true_poses(tmp_path: Path) -> None:
    out = tmp_path / "grid"
    options = ["--grid", "5", "--stations", "1,13,25", "--views", "0"]
    assert main(["simulate", "--out", str(out), *options, "--arrival-error", "0.1,5"]) == 0
    session = load_session(out)
    calibration = session.calibration
    assert calibration.stations is not None and calibration.stations.reference == 13
    assert sorted(calibration.stations.to_reference) == list(range(1, 26))
    truth = json.loads((out / "truth.json").read_text())
    assert truth["grid"] == 5 and truth["arrival_error"] == {"sigma_m": 0.1, "sigma_deg": 5.0}
    assert len(truth["plants"]) == 64
    assert sorted(truth["stations"], key=int) == ["1", "13", "25"]
    corner = truth["stations"]["25"]
    assert corner["nominal_pose"] == {"x": 6.4, "y": 6.4, "yaw_deg": 0.0}
    error = corner["arrival_error"]
    assert error["x_m"] == pytest.approx(corner["true_pose"]["x"] - 6.4)
    assert 0.0 < np.hypot(error["x_m"], error["y_m"]) < 0.6
    assert set(truth["T_field_camera"]) == {"1", "13", "25"}


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--grid", "10"], "--grid"),
        (["--grid", "3", "--stations", "10"], "--stations"),
        (["--arrival-error", "0.2,1"], "--arrival-error"),
        (["--arrival-error", "0.05"], "--arrival-error"),
        (["--arrival-error", "a,b"], "--arrival-error"),
        (["--localisation-error", "0.3,1"], "--localisation-error"),
        (["--localisation-error", "0.1,11"], "--localisation-error"),
        (["--localisation-error", "0.1"], "--localisation-error"),
        (["--scene", "checkerboard", "--grid", "5"], "--grid"),
    ],
)
def test_bad_grid_and_arrival_options_give_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], options: list[str], message: str
) -> None:
    assert main(["simulate", "--out", str(tmp_path / "s"), *options]) == 1
    error = capsys.readouterr().err.strip()
    assert error.startswith("fieldapp simulate: ") and message in error and "\n" not in error
    assert not (tmp_path / "s").exists()
