"""``fieldapp camera``: info, grab and stream on replay; clear errors, exit 1, no traceback."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from fieldapp.cli import main


@pytest.fixture(autouse=True)
def no_user_settings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FIELDAPP_SETTINGS", str(tmp_path / "absent.yaml"))


def test_info_prints_intrinsics_and_serial(
    hand_session: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["camera", "--backend", "replay", "--session", str(hand_session), "info"]) == 0
    out = capsys.readouterr().out
    assert "camera: replay (simulated), recorded session, serial replay:hand-1" in out
    assert "8 x 6 px, fx 10.00 fy 10.50 cx 4.00 cy 3.00, distortion [0.01, 0.0" in out


def test_grab_writes_the_median_frame(
    hand_session: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "grab"
    args = ["camera", "--backend", "replay", "--session", str(hand_session), "--fast"]
    assert main([*args, "grab", "--out", str(out), "--frames", "3"]) == 0
    assert "quality:" in capsys.readouterr().out
    depths = np.stack([np.load(hand_session / f"depth{i}.npy") for i in range(3)])
    valid = np.isfinite(depths).sum(axis=0) >= 2
    with np.errstate(invalid="ignore"):
        expected_mm = np.rint(np.nanmedian(np.where(valid, depths, np.nan), axis=0) * 1000)
    written = cv2.imread(str(out / "depth.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(written, np.nan_to_num(expected_mm).astype(np.uint16))
    document = json.loads((out / "frame.json").read_text())
    assert document["frames_combined"] == 3 and document["intrinsics"]["fy"] == 10.5
    assert 0.0 <= document["quality"]["fill_rate"] <= 1.0


def test_stream_prints_rate_and_quality(
    hand_session: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["camera", "--backend", "replay", "--session", str(hand_session)]
    assert main([*args, "stream", "--seconds", "0.5"]) == 0
    out = capsys.readouterr().out
    frames = int(out.split("stream: ")[1].split(" frames")[0])
    assert 5 <= frames <= 20  # the replay loops at 30 fps
    assert "fps" in out and "quality:" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--backend", "replay"], "--session: the replay backend needs a session folder"),
        (["--backend", "replay", "--session", "/nonexistent"], "no such folder"),
        (["--backend", "kinect2"], "libfreenect2"),
        (["--backend", "realsense", "--recording", "/nonexistent.db3"], "no such RealSense"),
    ],
)
def test_errors_are_one_line_and_exit_1(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["camera", *args, "info"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("fieldapp camera: ") and message in err
    assert "Traceback" not in err


def test_bad_grab_options(hand_session: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["camera", "--backend", "replay", "--session", str(hand_session)]
    assert main([*args, "grab", "--out", str(hand_session / "x"), "--frames", "0"]) == 1
    assert "--frames: 0 is outside 1..100" in capsys.readouterr().err
    assert main([*args, "stream", "--seconds", "-1"]) == 1
    assert "--seconds: -1.0 is outside" in capsys.readouterr().err
