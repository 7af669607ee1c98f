"""The plant-on-turntable scene: the plant turns, the room does not; the session it writes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.geometry import rotation_z, transform_points
from devices.sim.render import SensorModel
from devices.sim.turntable_scene import TurntableRig, turntable_captures, turntable_plant
from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.verify import verify_session


def test_view_step_maps_the_next_view_of_a_plant_point_into_this_one() -> None:
    rig = TurntableRig()
    C_inv = np.linalg.inv(rig.T_table_camera)
    plant = turntable_plant(0, 0).vertices_m[::50]
    for angle_deg in (0.0, 45.0, 130.0):
        here = transform_points(C_inv, plant @ rotation_z(angle_deg).T)
        after = transform_points(C_inv, plant @ rotation_z(angle_deg + rig.view_step_deg).T)
        np.testing.assert_allclose(transform_points(rig.T_view_next(), after), here, atol=1e-9)


def test_the_plant_turns_and_the_room_stands_still() -> None:
    frames = list(
        turntable_captures(
            turntable_plant(1, 0), TurntableRig(), [0, 2], 1, sensor=SensorModel(noise=False)
        )
    )
    first, second = (np.nan_to_num(c.frame.depth_m, nan=0.0) for c in frames)
    room = (first > 1.6) & (second > 1.6)  # the walls and the cabinet, far behind the table
    assert room.sum() > 20_000
    np.testing.assert_array_equal(first[room], second[room])
    changed = np.abs(first - second) > 0.005  # the plant (about 1.1 m away) has turned
    assert changed.sum() > 500
    assert np.median(np.minimum(first, second)[changed]) < 1.3
    assert frames[1].reported_angle_deg == 90.0
    assert frames[1].true_angle_deg != 90.0  # the table stops off the commanded angle


def test_cli_writes_a_depth_only_turntable_session(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "table"
    options = ["--scene", "turntable", "--depth-only", "--views", "0,1", "--seed", "2"]
    assert main(["simulate", "--out", str(out), *options]) == 0
    assert "2 captures of the turntable scene" in capsys.readouterr().out
    assert verify_session(out).usable
    session = load_session(out)
    assert session.document.turntable is not None
    assert session.document.turntable.carries == "plant"
    assert [c.color for c in session.captures] == [None, None]
    assert {c.station for c in session.captures} == {1}
    assert not list(out.rglob("color*"))
    assert getattr(session.calibration.view_step, "nominal", None)
    truth = json.loads((out / "truth.json").read_text())
    (plant,) = truth["plants"]
    assert 15 < plant["height_cm"] < 50 and 15 < plant["width_cm"] < 70


def test_cli_writes_a_depth_only_plot_session(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "plot"
    assert (
        main(["simulate", "--out", str(out), "--depth-only", "--stations", "5", "--views", "0"])
        == 0
    )
    capsys.readouterr()
    assert verify_session(out).usable
    (capture,) = load_session(out).captures
    assert capture.color is None and (out / capture.depth).is_file()
    assert not list(out.rglob("color*"))
    assert json.loads((out / "session.json").read_text())["simulated"]["depth_only"] is True


@pytest.mark.parametrize(
    ("scene", "option", "takers"),
    [
        ("turntable", ["--depth-offset", "0.02"], "plot, spheres, soil and checkerboard"),
        ("turntable", ["--color-shift", "1,0"], "plot, spheres, soil and checkerboard"),
        ("turntable", ["--grid", "4"], "plot, spheres, soil and checkerboard"),
        ("turntable", ["--stage", "touching"], "plot"),
        ("soil", ["--lean", "10"], "plot"),
        ("spheres", ["--clod-size", "12"], "plot"),
        ("plot", ["--plants"], "spheres"),
        ("plot", ["--intrinsics-images", "5"], "checkerboard"),
    ],
)
def test_an_option_the_scene_would_ignore_is_refused_by_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], scene: str, option: list[str], takers: str
) -> None:
    out = tmp_path / "s"
    assert main(["simulate", "--out", str(out), "--scene", scene, *option]) == 1
    error = capsys.readouterr().err
    assert f"{option[0]}: the {scene} scene does not take it (only {takers})" in error
    assert not out.exists()  # nothing written that lacks what was asked for
