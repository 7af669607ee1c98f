"""``fieldapp simulate``: a spec-conforming session, nominal calibration, truth, clear errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.geometry import pose_error
from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.verify import verify_session


def test_small_plot_session_is_valid_and_nominal(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "session"
    assert main(["simulate", "--out", str(out), "--stations", "4,5", "--views", "0,1"]) == 0
    assert "4 captures" in capsys.readouterr().out
    assert verify_session(out).usable
    session = load_session(out)
    assert sorted((c.station, c.view) for c in session.captures) == [(4, 0), (4, 1), (5, 0), (5, 1)]
    truth = json.loads((out / "truth.json").read_text())
    assert len(truth["plants"]) == 16
    assert set(truth["T_field_camera"]) == {"4", "5"}
    calibration = session.calibration
    assert calibration.ground is not None and calibration.stations is not None
    # the nominal reference pose is a few cm / degrees from where station 5 really stood
    T_true = np.array(truth["T_field_camera"]["5"])
    distance_m, angle_deg = pose_error(calibration.ground.matrix, T_true)
    assert 0.002 < distance_m < 0.15
    assert 0.05 < angle_deg < 6.0
    # reported base poses are near the nominal map poses (station 5 at map 1.6, 1.6)
    pose = next(c.base_pose for c in session.captures if c.station == 5)
    assert pose is not None and abs(pose.x - 1.6) < 0.1 and abs(pose.y - 1.6) < 0.1


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--scene", "forest"], "--scene"),
        (["--seed", "abc"], "--seed"),
        (["--day", "-3"], "--day"),
        (["--stations", "0,5"], "--stations"),
        (["--stations", "4-x"], "--stations"),
        (["--views", "8"], "--views"),
    ],
)
def test_bad_options_give_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], options: list[str], message: str
) -> None:
    assert main(["simulate", "--out", str(tmp_path / "s"), *options]) == 1
    error = capsys.readouterr().err.strip()
    assert error.startswith("fieldapp simulate: ") and message in error
    assert "\n" not in error
    assert not (tmp_path / "s").exists()


def test_refuses_to_overwrite_a_session(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s"
    assert main(["simulate", "--out", str(out), "--stations", "5", "--views", "0"]) == 0
    assert main(["simulate", "--out", str(out), "--stations", "5", "--views", "0"]) == 1
    assert "already exists" in capsys.readouterr().err


def test_unwritable_output_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert main(["simulate", "--out", str(blocker / "s"), "--stations", "5", "--views", "0"]) == 1
    error = capsys.readouterr().err.strip()
    assert error.startswith("fieldapp simulate: --out: cannot write") and "\n" not in error
    assert main(["simulate", "--out", str(blocker)]) == 1
    assert "not a folder" in capsys.readouterr().err
