"""Depth and colour as a Kinect v2 gives them before undistortion (a recorder of raw frames):
the lens's radial distortion in the images, and in the calibration (``simulate
--lens-distortion``). Read through the calibration's distortion (``backproject.ray_table``,
OpenCV's ``undistortPoints``), the plot registers and measures as an undistorted one; read as
if there were none, its stations land millimetres off.

One simulated 2 x 2 plot (4 plants, 32 frames, about 10 s), reconstructed twice.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from devices.camera.frames import KINECT_V2_DISTORTION
from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.settings import ReconstructionSettings

from .test_end_to_end import matched_errors
from .test_large_arrival import station_errors

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def raw_frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("distorted") / "session"
    options = ["--seed", "1", "--grid", "2", "--lens-distortion"]
    assert main(["simulate", "--out", str(folder), *options]) == 0
    return folder


def _reconstructed(folder: Path) -> Reconstruction:
    return run_reconstruction(load_session(folder), ReconstructionSettings())


def test_frames_with_their_lens_distortion_are_read_through_it(raw_frames: Path) -> None:
    calibration = json.loads((raw_frames / "calibration.json").read_text())
    assert calibration["depth_camera"]["distortion"] == list(KINECT_V2_DISTORTION)
    result = _reconstructed(raw_frames)
    truth = json.loads((raw_frames / "truth.json").read_text())
    errors = matched_errors(result, truth)  # every plant found, once
    assert len(result.plants) == len(truth["plants"]) == 4
    assert np.sqrt(np.mean(errors["dh_cm"] ** 2)) <= 0.8  # measured 0.50
    assert np.sqrt(np.mean(errors["dw_cm"] ** 2)) <= 1.0  # measured 0.53
    worst_mm = max(1000 * shift for shift, _ in station_errors(result, raw_frames).values())
    assert worst_mm <= 2.0  # measured 0.7


def test_the_same_frames_read_as_undistorted_land_off(raw_frames: Path, tmp_path: Path) -> None:
    """The control: the distortion matters, so the test above checks it is used."""
    ignored = tmp_path / "ignored"
    shutil.copytree(raw_frames, ignored)
    calibration = json.loads((ignored / "calibration.json").read_text())
    calibration["depth_camera"]["distortion"] = [0.0] * 5
    (ignored / "calibration.json").write_text(json.dumps(calibration))
    result = _reconstructed(ignored)
    worst_mm = max(1000 * shift for shift, _ in station_errors(result, ignored).values())
    assert worst_mm > 3.0  # measured 5.9
