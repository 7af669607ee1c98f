"""Session and calibration round trips, reading captures, durable writing."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from fieldapp.errors import FieldappError, FormatError
from fieldapp.io import durable
from fieldapp.io.calibration import Calibration, DepthCamera, load_calibration, save_calibration
from fieldapp.io.session import BasePose, load_session
from fieldapp.io.writer import SessionWriter
from fieldapp.verify import verify_session


def test_reads_another_tools_session(make_spec_session):
    session = load_session(make_spec_session())
    assert session.id == "2022-06-07-plot-a"
    assert session.stations() == [1, 2]
    assert session.calibration.view_step is not None
    assert session.calibration.view_step.views_per_turn == 4
    images = list(session.iter_captures())
    assert len(images) == 8
    first = images[0]
    assert first.depth_m.dtype == np.float32 and first.depth_m.shape == (48, 64)
    assert np.isnan(first.depth_m[0, 0])  # 0 = no measurement
    assert np.nanmin(first.depth_m) >= 0.5 and np.nanmax(first.depth_m) < 4.5
    assert first.color.dtype == np.uint8 and first.color.shape == (48, 64, 3)
    # unknown fields are kept, not lost
    assert session.document.model_extra == {"operator": "another tool"}
    assert session.captures[0].model_extra == {"exposure_us": 1200}


def test_calibration_round_trip_keeps_values_and_unknown_fields(make_spec_session, tmp_path):
    original = load_calibration(make_spec_session() / "calibration.json")
    path = tmp_path / "copy.json"
    save_calibration(path, original)
    again = load_calibration(path)
    assert again.model_extra == {"vendor_note": "fields a reader does not know are ignored"}
    assert again.stations is not None and original.stations is not None
    assert sorted(again.stations.to_reference) == [1, 2]
    np.testing.assert_array_equal(again.stations.to_reference[1], original.stations.to_reference[1])
    assert json.loads(path.read_text())["stations"]["to_reference"].keys() == {"1", "2"}


def test_chaining_view_step_is_the_papers_equation_9(make_spec_session):
    view_step = load_session(make_spec_session()).calibration.view_step
    assert view_step is not None
    R, t = view_step.matrix[:3, :3], view_step.matrix[:3, 3]
    p3 = np.array([0.3, -0.2, 1.7])
    expected = np.linalg.matrix_power(R, 3) @ p3 + (R @ R + R + np.eye(3)) @ t
    T = view_step.T_view0_view(3)
    np.testing.assert_allclose(T[:3, :3] @ p3 + T[:3, 3], expected, atol=1e-12)


@pytest.fixture
def calibration(make_spec_session) -> Calibration:
    return load_calibration(make_spec_session(name="template") / "calibration.json")


def test_writer_round_trip(tmp_path, calibration):
    rng = np.random.default_rng(3)
    depth_m = rng.uniform(0.5, 4.5, (48, 64)).astype(np.float32)
    depth_m[10, 10] = np.nan
    color = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    ir = rng.integers(0, 65535, (48, 64), dtype=np.uint16)
    writer = SessionWriter.create(tmp_path / "s", "test-session", calibration)
    writer.add_capture(
        2, 0, depth_m, color, ir=ir, angle_deg=0.02, base_pose=BasePose(x=0.1, y=0.2, yaw_deg=1.5)
    )
    writer.add_capture(2, 1, depth_m, color, target="board-a")

    session = load_session(tmp_path / "s")
    assert [(c.station, c.view) for c in session.captures] == [(2, 0), (2, 1)]
    assert getattr(session.captures[1], "target", None) == "board-a"
    assert session.captures[0].base_pose == BasePose(x=0.1, y=0.2, yaw_deg=1.5)
    images = session.read_capture(session.captures[0], with_ir=True)
    np.testing.assert_allclose(images.depth_m, depth_m, atol=0.0005 + 1e-6, equal_nan=True)
    np.testing.assert_array_equal(images.color, color)
    assert images.ir is not None
    np.testing.assert_array_equal(images.ir, ir)
    assert verify_session(tmp_path / "s").usable


def test_writer_refuses_duplicates_and_wrong_sizes(tmp_path, calibration):
    writer = SessionWriter.create(tmp_path / "s", "x", calibration)
    depth = np.ones((48, 64), np.float32)
    color = np.zeros((48, 64, 3), np.uint8)
    writer.add_capture(1, 0, depth, color)
    with pytest.raises(FieldappError, match="already captured"):
        writer.add_capture(1, 0, depth, color)
    with pytest.raises(ValueError, match="calibration says"):
        writer.add_capture(1, 1, np.ones((10, 10), np.float32), color)
    with pytest.raises(FieldappError, match="already exists"):
        SessionWriter.create(tmp_path / "s", "x", calibration)


def test_reopened_writer_continues_the_session(tmp_path, calibration):
    depth = np.ones((48, 64), np.float32)
    color = np.zeros((48, 64, 3), np.uint8)
    SessionWriter.create(tmp_path / "s", "x", calibration).add_capture(1, 0, depth, color)
    writer = SessionWriter.open(tmp_path / "s")
    assert writer.has(1, 0) and not writer.has(1, 1)
    writer.add_capture(1, 1, depth, color)
    assert len(load_session(tmp_path / "s").captures) == 2


def test_a_failed_listing_loses_nothing_already_captured(tmp_path, calibration, monkeypatch):
    depth = np.ones((48, 64), np.float32)
    color = np.zeros((48, 64, 3), np.uint8)
    writer = SessionWriter.create(tmp_path / "s", "x", calibration)
    writer.add_capture(1, 0, depth, color)

    def crash(*args: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(durable.os, "replace", crash)
    with pytest.raises(OSError, match="No space"):
        writer.add_capture(1, 1, depth, color)
    monkeypatch.undo()
    session = load_session(tmp_path / "s")
    assert [(c.station, c.view) for c in session.captures] == [(1, 0)]
    assert not writer.has(1, 1)  # memory agrees with the disk
    leftovers = [p for p in (tmp_path / "s").rglob("*.tmp")]
    assert leftovers == []


def test_durable_write_replaces_whole_or_not_at_all(tmp_path, monkeypatch):
    path = tmp_path / "doc.json"
    durable.write_json_durably(path, {"version": 1})

    def crash(*args: object) -> None:
        raise KeyboardInterrupt  # a crash between writing and renaming

    monkeypatch.setattr(durable.os, "replace", crash)
    with pytest.raises(KeyboardInterrupt):
        durable.write_json_durably(path, {"version": 2})
    monkeypatch.undo()
    assert json.loads(path.read_text()) == {"version": 1}
    assert os.listdir(tmp_path) == ["doc.json"]


def test_durable_json_refuses_nan(tmp_path):
    with pytest.raises(ValueError, match="not JSON compliant"):
        durable.write_json_durably(tmp_path / "x.json", {"v": float("nan")})
    assert not (tmp_path / "x.json").exists()


def test_depth_camera_converts_to_device_intrinsics():
    camera = DepthCamera(width=512, height=424, fx=365.18, fy=364.49, cx=256.0, cy=209.59)
    intrinsics = camera.intrinsics()
    assert intrinsics.K[0, 0] == 365.18 and intrinsics.K[1, 2] == 209.59
    assert DepthCamera.from_intrinsics(intrinsics) == camera


def test_a_session_without_an_id_is_read_under_its_folder_s_name(make_spec_session, edit_json):
    """The spec shows ``id`` in its example but lists no top-level field as required; a
    session another recorder wrote without one was refused ("id: Field required")."""
    folder = make_spec_session()
    edit_json(folder / "session.json", lambda d: (d.pop("id"), d.pop("created")))
    session = load_session(folder)
    assert session.id == folder.resolve().name
    assert verify_session(folder).usable


def test_a_session_needs_view_step_and_stations(make_spec_session, edit_json):
    folder = make_spec_session()
    edit_json(folder / "calibration.json", lambda d: (d.pop("view_step"), d.pop("stations")))
    with pytest.raises(FormatError) as error:
        load_session(folder)
    assert [p.field for p in error.value.problems] == ["view_step", "stations"]
    assert "needed to join the views" in str(error.value)


def test_durable_files_honour_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        durable.write_json_durably(tmp_path / "shared.json", {"v": 1})
    finally:
        os.umask(old)
    assert (tmp_path / "shared.json").stat().st_mode & 0o777 == 0o644
