"""``SensorModel.sun_ir`` (``fieldapp simulate --sunlight S``): a time-of-flight pixel's noise
grows with the sun's infrared over the light it gets back, and a return drowned in it gives no
depth; with no sun the sensor is as it was."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from devices.camera.frames import KINECT_V2_PAPER
from devices.sim.render import Renderer, SensorModel
from devices.sim.rig import RigGeometry
from devices.sim.scene import Scene, empty_scene
from devices.sim.sensor import FULL_SUN_IR, sensor_depth
from devices.sim.soil import SoilSpec
from fieldapp.cli import main

FLAT = SoilSpec(relief_m=0.0, clod_m=0.0)


@pytest.fixture(scope="module")
def flat_scene() -> Scene:
    return empty_scene(seed=1, soil_spec=FLAT)


def _robust_sigma(residual: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(residual - np.median(residual))))


def test_noise_grows_as_the_square_root_of_ambient_over_returned_light() -> None:
    shape = (200, 200)
    depth = np.full(shape, 2.0, np.float32)
    facing = np.ones(shape, np.float32)
    ir = np.full(shape, 1000.0, np.float32)  # bright enough that the dim-return term is 1
    sensor = SensorModel(flying_fraction=0.0)
    shade = sensor_depth(sensor, depth, facing, ir, np.random.default_rng(0))
    for share in (3.0, 15.0):
        ambient = np.full(shape, share * 1000.0, np.float32)
        sunny = sensor_depth(sensor, depth, facing, ir, np.random.default_rng(0), ambient)
        ratio = _robust_sigma(sunny - 2.0) / _robust_sigma(shade - 2.0)
        assert ratio == pytest.approx(np.sqrt(1.0 + share), rel=0.05)
        assert abs(float(np.nanmean(sunny)) - 2.0) < 1e-3  # noisier, not biased
        assert np.isfinite(sunny).all()  # below the sensor's confidence limit


def test_a_return_drowned_in_ambient_light_gives_no_depth() -> None:
    shape = (100, 100)
    depth = np.full(shape, 2.0, np.float32)
    facing, ir = np.ones(shape, np.float32), np.full(shape, 500.0, np.float32)
    sensor = SensorModel()
    rng = np.random.default_rng(1)
    halfway = (sensor.drowned_start + sensor.drowned_end) / 2
    missing = [
        np.isnan(
            sensor_depth(sensor, depth, facing, ir, rng, np.full(shape, share * 500, np.float32))
        ).mean()
        for share in (sensor.drowned_start / 2, halfway, sensor.drowned_end * 1.5)
    ]
    assert missing[0] < 0.01
    assert missing[1] == pytest.approx(0.5, abs=0.05)
    assert missing[2] == 1.0


def test_sunlit_ground_is_noisier_far_away_and_shade_is_unchanged(flat_scene: Scene) -> None:
    rig = RigGeometry()
    T = rig.T_field_camera(rig.station_pose(5), 30.0)
    exact = Renderer(flat_scene, KINECT_V2_PAPER, SensorModel(noise=False)).render(T).depth_m
    shade = Renderer(flat_scene, KINECT_V2_PAPER).render(T, np.random.default_rng(3)).depth_m
    zero_sun = Renderer(flat_scene, KINECT_V2_PAPER, SensorModel(sun_ir=0.0))
    np.testing.assert_array_equal(shade, zero_sun.render(T, np.random.default_rng(3)).depth_m)
    sun = Renderer(flat_scene, KINECT_V2_PAPER, replace(SensorModel(), sun_ir=FULL_SUN_IR))
    sunny = sun.render(T, np.random.default_rng(3)).depth_m
    for low, high, least, most in ((1.4, 1.7, 2.0, 5.0), (2.0, 2.3, 2.5, 12.0)):
        band = (exact >= low) & (exact <= high)
        measured = band & np.isfinite(sunny) & np.isfinite(shade)
        ratio = _robust_sigma((sunny - exact)[measured]) / _robust_sigma((shade - exact)[measured])
        assert least < ratio < most, (low, high, ratio)
    far = (exact >= 2.6) & (exact <= 3.2)
    assert np.isnan(sunny[far]).mean() > np.isnan(shade[far]).mean() + 0.2  # range shortened


def test_cli_writes_the_sunlight_into_the_session(tmp_path: Path) -> None:
    out = tmp_path / "s"
    options = ["--sunlight", "0.5", "--stations", "5", "--views", "0"]
    assert main(["simulate", "--out", str(out), *options]) == 0
    assert json.loads((out / "session.json").read_text())["simulated"]["sunlight"] == 0.5


@pytest.mark.parametrize(
    ("text", "message"),
    [("2", "--sunlight: 2 is outside 0..1"), ("bright", "--sunlight: 'bright' is not a number")],
)
def test_a_bad_sunlight_is_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    assert main(["simulate", "--out", str(tmp_path / "s"), "--sunlight", text]) == 1
    assert message in capsys.readouterr().err
