"""fieldapp.calib.service: the one place the CLI and the wizards merge, judge and save a
calibration; provenance as typed fields written as before."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fieldapp.calib import service
from fieldapp.calib.verdict import Level, views_verdict
from fieldapp.calib.views import ViewStepResult
from fieldapp.errors import FieldappError, FormatError
from fieldapp.io.calibration import (
    CALIBRATION_FORMAT,
    Calibration,
    DepthCamera,
    Ground,
    ViewStep,
    load_calibration,
)

CAMERA = {"width": 512, "height": 424, "fx": 365.0, "fy": 365.0, "cx": 256.0, "cy": 212.0}


def _turn(angle_deg: float) -> np.ndarray:
    a = np.radians(angle_deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:3, 3] = [0.1, 0.0, 0.02]
    return T


def _views_result(rmse_m: float = 0.0015, angle_deg: float = 45.1) -> ViewStepResult:
    return ViewStepResult(_turn(angle_deg), angle_deg, rmse_m, ["0-1 board a", "1-2 board a"], 96)


def test_provenance_is_a_typed_field_and_written_as_before(tmp_path: Path) -> None:
    """Files with provenance (and unknown extras beside it) read and write back unchanged."""
    document = {
        "format": CALIBRATION_FORMAT,
        "depth_camera": {
            **CAMERA,
            "distortion": [0.0] * 5,
            "depth_scale": 1000.0,
            "calibrated": {"date": "2026-05-01T10:00:00+02:00", "rig_serial": "KV2", "rms_px": 0.2},
        },
        "view_step": {
            "angle_deg": 45.0,
            "matrix": _turn(45.0).tolist(),
            "calibrated": {"method": "svd", "pairs": ["0-1"], "per": {"a": 1}},
            "refined_with_stations": {"solved_angle_deg": 45.02},
            "nominal": {"angle_deg": 45.0},
        },
        "ground": {"matrix": np.eye(4).tolist(), "calibrated": {"rms_mm": 2.5}},
    }
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(document))
    calibration = load_calibration(path)
    assert "calibrated" in DepthCamera.model_fields and "calibrated" in Ground.model_fields
    assert "refined_with_stations" in ViewStep.model_fields
    assert calibration.depth_camera.calibrated == document["depth_camera"]["calibrated"]
    assert calibration.view_step is not None and calibration.view_step.calibrated is not None
    assert calibration.view_step.calibrated["method"] == "svd"
    service.save(path, calibration)
    assert json.loads(path.read_text()) == json.loads(json.dumps(document))


def test_bad_provenance_names_the_field(tmp_path: Path) -> None:
    path = tmp_path / "calibration.json"
    document = {"format": CALIBRATION_FORMAT, "depth_camera": {**CAMERA, "calibrated": "yes"}}
    path.write_text(json.dumps(document))
    with pytest.raises(FormatError, match=r"depth_camera\.calibrated"):
        load_calibration(path)


def test_view_step_merged_with_provenance_and_previous_kept(tmp_path: Path) -> None:
    path = tmp_path / "calibration.json"
    first = Calibration(format=CALIBRATION_FORMAT, depth_camera=DepthCamera(**CAMERA))
    assert service.in_force(path) is None
    assert service.save(path, first) is None
    current = service.in_force(path)
    assert current is not None
    merged = service.merge_view_step(current, _views_result(), 45.0, "RIG-7")
    previous = service.save(path, merged)
    assert previous is not None and load_calibration(previous).view_step is None
    saved = json.loads(path.read_text())["view_step"]
    assert saved["angle_deg"] == 45.0
    np.testing.assert_allclose(saved["matrix"], _turn(45.1), atol=1e-12)
    figures = saved["calibrated"]
    assert figures["rig_serial"] == "RIG-7" and figures["rmse_mm"] == 1.5
    assert figures["solved_angle_deg"] == 45.1 and figures["points"] == 96
    assert figures["software"].startswith("fieldapp ") and figures["date"]


def test_save_names_the_file_it_cannot_write(tmp_path: Path) -> None:
    (tmp_path / "a-file").write_text("not a folder")
    path = tmp_path / "a-file" / "calibration.json"
    calibration = Calibration(format=CALIBRATION_FORMAT, depth_camera=DepthCamera(**CAMERA))
    with pytest.raises(FieldappError, match=r"a-file/calibration\.json: cannot write"):
        service.save(path, calibration)


def test_stations_need_a_view_step_first(tmp_path: Path) -> None:
    calibration = Calibration(format=CALIBRATION_FORMAT, depth_camera=DepthCamera(**CAMERA))
    with pytest.raises(FieldappError, match=r"rig\.json has no view_step"):
        service.stations_job(calibration, None, None, 5, "rig.json")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("rmse_m", "angle_deg", "level"),
    [(0.0015, 45.1, Level.GOOD), (0.003, 45.1, Level.USABLE), (0.0015, 48.0, Level.REDO)],
)
def test_the_verdict_is_graded_in_the_core(rmse_m: float, angle_deg: float, level: Level) -> None:
    assert views_verdict(_views_result(rmse_m, angle_deg), 45.0).level is level
