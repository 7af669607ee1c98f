"""Plant-on-turntable sessions: the room masked, the views joined about the table's axis (the
commanded turns refined by ICP when there was no board), one plant measured."""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from devices.geometry import transform_points
from devices.sim.turntable_scene import TurntableRig
from fieldapp.cli._simulate_turntable import write_turntable_session
from fieldapp.errors import FormatError
from fieldapp.io.calibration import T_view0_view
from fieldapp.io.session import load_session
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.recon.turntable_axis import place_views, table_axis

pytestmark = pytest.mark.slow  # a few small simulated sessions (8 views, one station)


def test_the_table_axis_comes_from_the_view_step() -> None:
    rig = TurntableRig()
    axis = table_axis(rig.T_view_next(), rig.view_step_deg)
    T_camera_table = np.linalg.inv(rig.T_table_camera)
    on_axis = transform_points(T_camera_table, np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5]]))
    up = on_axis[1] - on_axis[0]
    np.testing.assert_allclose(axis.up, up / np.linalg.norm(up), atol=1e-9)
    offset = on_axis[0] - axis.point_m
    np.testing.assert_allclose(offset - (offset @ axis.up) * axis.up, 0.0, atol=1e-9)
    for view in range(8):
        np.testing.assert_allclose(
            axis.T_view0_view(view * rig.view_step_deg),
            T_view0_view(rig.T_view_next(), view),
            atol=1e-9,
        )


SEEDS = {0: False, 1: True, 2: True}
"""The sessions (seed: depth-only): a table stopping about 2 degrees off the commanded angles."""


@dataclass(frozen=True)
class Turned:
    folder: Path
    truth: dict
    result: Reconstruction


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Turned]:
    """Each seed's session, simulated and reconstructed once for the module."""
    made = {}
    for seed, depth_only in SEEDS.items():
        folder = tmp_path_factory.mktemp("table") / f"seed{seed}"
        rig = TurntableRig(angle_sigma_deg=2.0)
        write_turntable_session(folder, seed, 0, list(range(8)), depth_only, rig)
        truth = json.loads((folder / "truth.json").read_text())
        result = run_reconstruction(load_session(folder), ReconstructionSettings())
        made[seed] = Turned(folder, truth, result)
    return made


@pytest.mark.timeout(900)
@pytest.mark.parametrize("seed", sorted(SEEDS))
def test_the_plant_is_found_and_measured_and_the_room_is_not_in_it(
    sessions: dict[int, Turned], seed: int
) -> None:
    result, truth = sessions[seed].result, sessions[seed].truth
    (plant,) = result.plants
    (true,) = truth["plants"]
    assert abs(plant.traits.height_m * 100 - true["height_cm"]) <= 1.0
    assert abs(plant.traits.width_m * 100 - true["width_cm"]) <= 1.5
    # nothing of the room in it: every point within the working volume about the axis
    assert np.hypot(*plant.cloud.points[:, :2].T).max() <= truth["working_radius_m"] + 0.01
    assert plant.cloud.points[:, 2].min() > -0.02
    expected = "geometry: no colour" if SEEDS[seed] else "colour"
    assert expected in result.separation[1]


def _rms(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(errors**2)))


@pytest.mark.parametrize("seed", sorted(SEEDS))
def test_icp_about_the_axis_corrects_a_slipping_table(
    sessions: dict[int, Turned], seed: int
) -> None:
    """ICP of the plant about the axis brings the views' turns closer to the truth."""
    true = np.array([c["angle_deg"] for c in sessions[seed].truth["captures"]])
    commanded = np.arange(8) * 45.0
    report = sessions[seed].result.report()["turntable"]
    assert report["refined_by_icp"] is True
    refined = np.array(report["view_turns_deg"])
    assert _rms(refined - true) < _rms(commanded - true)
    assert _rms(refined - true) <= 1.0


@pytest.mark.timeout(600)
def test_without_the_turntable_field_the_room_is_smeared_into_the_plant(
    sessions: dict[int, Turned], tmp_path: Path
) -> None:
    """What the session field changes: a depth-only recording read as the paper's rig (the
    camera turning) has the room turning with the plant: phantom plants, a metres-wide one."""
    folder = tmp_path / "as-plot"
    shutil.copytree(sessions[1].folder, folder)
    document = json.loads((folder / "session.json").read_text())
    del document["turntable"]
    document["captures"] = document["captures"][:2]  # two views are enough to smear it
    (folder / "session.json").write_text(json.dumps(document))
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    (true,) = sessions[1].truth["plants"]
    widths = [p.traits.width_m * 100 for p in result.plants]
    assert len(result.plants) > 1 and max(widths) > 2 * true["width_cm"]


def test_commanded_angles_place_the_views_when_not_refined() -> None:
    rig = TurntableRig()
    axis = table_axis(rig.T_view_next(), rig.view_step_deg)
    angles = [10.0, 40.0, 70.5, 100.0]  # a 30-degree table, homed at 10 degrees
    turns, report = place_views(angles, [np.zeros((0, 3))] * 4, axis, [0, 1, 2, 3], False, [])
    assert turns == [0.0, 30.0, 60.5, 90.0]
    assert report["refined_by_icp"] is False


@pytest.mark.timeout(600)
def test_a_calibrated_view_step_is_used_as_it_is(
    sessions: dict[int, Turned], tmp_path: Path
) -> None:
    """A view step calibrated on a board (not ``nominal``) is not refined by ICP."""
    folder = tmp_path / "calibrated"
    shutil.copytree(sessions[0].folder, folder)
    calibration = json.loads((folder / "calibration.json").read_text())
    del calibration["view_step"]["nominal"]
    (folder / "calibration.json").write_text(json.dumps(calibration))
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    report = result.report()["turntable"]
    assert report["refined_by_icp"] is False
    assert report["view_turns_deg"] == [45.0 * k for k in range(8)]
    assert len(result.plants) == 1


def test_a_bad_turntable_field_is_named(sessions: dict[int, Turned], tmp_path: Path) -> None:
    folder = tmp_path / "bad"
    shutil.copytree(sessions[0].folder, folder)
    document = json.loads((folder / "session.json").read_text())
    document["turntable"] = {"carries": "robot"}
    (folder / "session.json").write_text(json.dumps(document))
    with pytest.raises(FormatError) as error:
        load_session(folder)
    assert "session.json" in str(error.value) and "turntable.carries" in str(error.value)
