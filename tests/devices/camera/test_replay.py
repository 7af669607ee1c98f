"""Replay: frame-exact on a simulator session and a hand-written one; order, loop, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.camera.base import CameraEnded, CameraFormatError
from devices.camera.replay import ReplayCamera
from fieldapp.cli import main
from fieldapp.io.session import load_session


@pytest.fixture(scope="module")
def sim_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sim") / "session"
    assert main(["simulate", "--out", str(folder), "--stations", "5", "--views", "0,3"]) == 0
    return folder


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.array_equal(a, b, equal_nan=True))


def test_simulator_session_replays_frame_exact(sim_session: Path) -> None:
    session = load_session(sim_session)
    expected = list(session.iter_captures(with_ir=True))
    with ReplayCamera(sim_session) as camera:
        assert camera.intrinsics == session.calibration.depth_camera.intrinsics()
        frames = [camera.read_frame() for _ in expected]
        with pytest.raises(CameraEnded, match="played all"):
            camera.read_frame()
    for frame, images in zip(frames, expected, strict=True):
        assert _same(frame.depth_m, images.depth_m) and frame.depth_m.dtype == np.float32
        assert _same(frame.color, images.color)
        assert images.ir is not None and frame.ir is not None and _same(frame.ir, images.ir)
        assert (frame.meta["station"], frame.meta["view"]) == images.capture.key[:2]
    assert [f.meta["frame_number"] for f in frames] == [0, 1]


def test_hand_written_session_replays_frame_exact(hand_session: Path) -> None:
    camera = ReplayCamera(hand_session)
    assert camera.intrinsics.fy == 10.5 and camera.intrinsics.distortion[0] == 0.01
    assert camera.depth_scale == 4000.0
    with camera:
        for index in range(3):
            frame = camera.read_frame()
            assert _same(frame.depth_m, np.load(hand_session / f"depth{index}.npy"))
            assert _same(frame.color, np.load(hand_session / f"rgb{index}.npy"))
            assert frame.meta["future_field"] == {"x": index}
    assert frame.ir is None
    tagged = camera.frame_at(1, 0, "board-a")
    assert tagged.ir is not None and _same(tagged.ir, np.load(hand_session / "ir1.npy"))
    assert np.isnan(tagged.depth_m[1, :3]).all() and np.isfinite(tagged.depth_m[1, 3:]).all()


def test_plays_by_station_and_view_in_the_given_order_and_loops(hand_session: Path) -> None:
    keys = [(1, 1), (2, 1), (1, 0, "board-a")]
    with ReplayCamera(hand_session, keys=keys, loop=True) as camera:
        frames = [camera.read_frame() for _ in range(7)]
    stations_views = [(f.meta["station"], f.meta["view"]) for f in frames]
    assert stations_views == [(1, 1), (2, 1), (1, 0)] * 2 + [(1, 1)]
    assert _same(frames[0].depth_m, frames[3].depth_m)
    assert _same(frames[0].depth_m, np.load(hand_session / "depth2.npy"))
    assert [f.meta["frame_number"] for f in frames] == list(range(7))


def test_missing_keys_and_files_are_named(hand_session: Path) -> None:
    with pytest.raises(CameraFormatError, match=r"no capture of station 1 view 0$"):
        ReplayCamera(hand_session, keys=[(1, 0)])  # only a tagged capture is there
    (hand_session / "img" / "c2.png").unlink()
    camera = ReplayCamera(hand_session, keys=[(1, 1)])
    with camera, pytest.raises(CameraFormatError, match=r"c2\.png: color: cannot read"):
        camera.read_frame()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("captures"), r"session\.json: captures: missing"),
        (lambda d: d["captures"][1].update(view="1"), r"captures\[1\]: view: missing or not"),
        (
            lambda d: d["captures"][0].update(depth="../x.png"),
            r"\[0\]: depth: .* not inside",
        ),
        (lambda d: d.update(calibration="nope.json"), r"nope\.json: file is missing"),
        (lambda d: d.update(captures=[]), "nothing to play"),
    ],
)
def test_bad_session_documents_are_typed_errors_naming_the_field(
    hand_session: Path, edit: object, message: str
) -> None:
    path = hand_session / "session.json"
    document = json.loads(path.read_text())
    edit(document)  # type: ignore[operator]
    path.write_text(json.dumps(document))
    with pytest.raises(CameraFormatError, match=message):
        ReplayCamera(hand_session)


def test_bad_calibration_and_images_are_typed_errors(hand_session: Path, tmp_path: Path) -> None:
    calibration = hand_session / "calib.json"
    document = json.loads(calibration.read_text())
    document["depth_camera"]["depth_scale"] = 0
    calibration.write_text(json.dumps(document))
    with pytest.raises(CameraFormatError, match="depth_camera: depth_scale: must be positive"):
        ReplayCamera(hand_session)
    calibration.write_text("{not json")
    with pytest.raises(CameraFormatError, match=r"calib\.json: not readable JSON"):
        ReplayCamera(hand_session)
    with pytest.raises(CameraFormatError, match="no such folder"):
        ReplayCamera(tmp_path / "absent")


def test_wrong_image_kinds_and_sizes_are_named(hand_session: Path) -> None:
    import cv2

    cv2.imwrite(str(hand_session / "img" / "d2.png"), np.zeros((6, 8), np.uint8))
    with (
        ReplayCamera(hand_session, keys=[(1, 1)]) as camera,
        pytest.raises(CameraFormatError, match=r"d2\.png: depth: must be a single-channel 16-bit"),
    ):
        camera.read_frame()
    cv2.imwrite(str(hand_session / "img" / "d2.png"), np.ones((5, 8), np.uint16))
    with (
        ReplayCamera(hand_session, keys=[(1, 1)]) as camera,
        pytest.raises(
            CameraFormatError,
            match=r"d2\.png: depth: size 8 x 5 differs from the calibration's 8 x 6",
        ),
    ):
        camera.read_frame()
    (hand_session / "img" / "c0.jpg").write_bytes(b"\xff\xd8 truncated")
    with pytest.raises(CameraFormatError, match=r"c0\.jpg: color: not a decodable image"):
        ReplayCamera(hand_session).frame_at(2, 1)
