"""``fieldapp import folder``: depth images (colour and IR where present) into a valid session."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from devices.geometry import transform_points
from fieldapp.cli import main
from fieldapp.errors import FieldappError, FormatError
from fieldapp.imports.camera import T_view_k_view_k1
from fieldapp.imports.folder import FolderOptions, import_folder
from fieldapp.io.calibration import T_view0_view
from fieldapp.io.images import depth_units_to_m, read_depth_units
from fieldapp.io.session import load_session
from fieldapp.verify import verify_session

W, H = 64, 48
INTRINSICS = "60,60,32,24"


def _depth_mm(index: int) -> np.ndarray:
    depth = np.full((H, W), 1500 + 10 * index, np.uint16)
    depth[:4, :4] = 0  # no measurement
    return depth


def _write(path: Path, image: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), image)


def test_depth_colour_and_ir_by_angle_pass_verify(tmp_path):
    source = tmp_path / "scan"
    for index, angle in enumerate((0, 45, 90)):
        _write(source / f"depth_{angle:03d}deg.png", _depth_mm(index))
        _write(source / f"color_{angle:03d}deg.png", np.full((H, W, 3), (30, 160, 40), np.uint8))
        _write(source / f"ir_{angle:03d}deg.png", np.full((H, W), 900 + index, np.uint16))
    out = tmp_path / "session"
    code = main(["import", "folder", str(source), "--intrinsics", INTRINSICS, "--out", str(out)])
    assert code == 0
    report = verify_session(out)
    assert report.usable, report.problems
    session = load_session(out)
    assert [(c.view, c.angle_deg) for c in session.captures] == [(0, 0.0), (1, 45.0), (2, 90.0)]
    assert session.calibration.view_step.angle_deg == 45.0
    images = session.read_capture(session.captures[2], with_ir=True)
    assert np.nanmax(images.depth_m) == pytest.approx(1.52)
    assert np.isnan(images.depth_m[0, 0])
    assert tuple(images.color[5, 5]) == (40, 160, 30)  # BGR on disk, RGB in memory
    assert images.ir is not None and images.ir[0, 0] == 902
    assert session.document.model_extra["imported"]["by"] == "folder"


def test_depth_only_turntable_folder_with_plain_names(tmp_path, capsys):
    """12 depth PNGs in millimetres, no colour, plain numbered names, a plant turning 30
    degrees at a time 1 m in front of a fixed camera."""
    source = tmp_path / "turntable"
    for index in range(12):
        _write(source / f"{index}.png", _depth_mm(index))
    out = tmp_path / "session"
    args = ["import", "folder", str(source), "--intrinsics", INTRINSICS, "--out", str(out)]
    assert main([*args, "--step-deg", "30", "--axis-distance-m", "1.0"]) == 0
    assert "12 captures imported, 12 depth-only" in capsys.readouterr().out
    assert verify_session(out).usable
    session = load_session(out)
    assert [c.view for c in session.captures] == list(range(12))  # 10.png after 9.png
    assert all(c.color is None for c in session.captures)
    document = json.loads((out / "session.json").read_text())
    assert all("color" not in c for c in document["captures"])
    with pytest.raises(FormatError, match="depth-only"):
        session.read_capture(session.captures[0])
    step = session.calibration.view_step
    assert step.nominal.startswith("fieldapp import")  # type: ignore[union-attr]
    assert session.missing() == []
    # the plant turns before a fixed camera: the reconstruction's turntable path is told so
    assert session.document.turntable is not None
    assert session.document.turntable.carries == "plant"


def test_turntable_step_turns_about_the_axis_before_the_camera():
    T = T_view_k_view_k1(30.0, 1.0)
    axis_points = np.array([[0.0, -0.3, 1.0], [0.0, 0.2, 1.0]])
    np.testing.assert_allclose(transform_points(T, axis_points), axis_points, atol=1e-12)
    np.testing.assert_allclose(T_view0_view(T, 12), np.eye(4), atol=1e-9)  # a full turn
    # the plant turning counter-clockwise seen from above (camera y down): a point right of
    # the axis (x > 0) seen at view 1 was nearer the camera at view 0
    moved = transform_points(T, np.array([[0.1, 0.0, 1.0]]))[0]
    assert moved[2] < 1.0 and moved[0] < 0.1
    np.testing.assert_allclose(T_view_k_view_k1(45.0, 0.0)[:3, 3], 0.0)


def test_opencv_yaml_intrinsics(tmp_path, shared_data):
    source = tmp_path / "scan"
    _write(source / "depth.png", np.full((480, 640), 1200, np.uint16))
    calibration = shared_data / "opencv-chessboard" / "left_intrinsics.yml"
    out = tmp_path / "session"
    result = import_folder(source, out, FolderOptions(calibration=calibration))
    assert result.captures == 1
    assert result.lines == [
        "view step unknown: 45 degrees written (give --step-deg for the real one)"
    ]
    camera = load_session(out).calibration.depth_camera
    assert camera.fx == pytest.approx(535.91573, rel=1e-6)
    assert camera.cx == pytest.approx(342.28315, rel=1e-6)
    assert camera.distortion[4] == pytest.approx(0.238392, rel=1e-5)
    _write(tmp_path / "small" / "depth.png", np.full((48, 64), 1200, np.uint16))
    with pytest.raises(FieldappError, match="calibrated for 640 x 480"):
        import_folder(tmp_path / "small", tmp_path / "s2", FolderOptions(calibration=calibration))


def test_unusable_files_are_skipped_and_said(tmp_path, capsys):
    source = tmp_path / "scan"
    _write(source / "s1_v0_depth.png", _depth_mm(0))
    _write(source / "s1_v0_color.png", np.zeros((H // 2, W // 2, 3), np.uint8))  # wrong size
    _write(source / "s1_v1_depth.png", np.zeros((H, W), np.uint8))  # 8-bit "depth"
    (source / "s1_v2_depth.png").write_bytes(b"")  # 0-byte file
    _write(source / "s1_v3_depth.png", _depth_mm(3))
    _write(source / "s1_v4_color.png", np.zeros((H, W, 3), np.uint8))  # no depth beside it
    _write(source / "notes_0.png", np.zeros((H, W), np.uint16))  # no kind in the name
    out = tmp_path / "session"
    args = ["import", "folder", str(source), "--intrinsics", INTRINSICS, "--out", str(out)]
    assert main([*args, "--step-deg", "45"]) == 0
    text = capsys.readouterr().out
    lines = [line for line in text.splitlines() if "not used" in line or "not imported" in line]
    assert len(lines) == 5, text
    assert any("s1_v0_color.png" in line and "registered to depth" in line for line in lines)
    assert any("s1_v1_depth.png" in line and "uint8" in line for line in lines)
    assert any("s1_v2_depth.png" in line and "not a decodable image" in line for line in lines)
    assert any("s1_v4_color.png" in line and "no depth image" in line for line in lines)
    assert any("notes_0.png" in line and "neither depth" in line for line in lines)
    session = load_session(out)
    assert [(c.view, c.color) for c in session.captures] == [(0, None), (3, None)]
    assert verify_session(out).usable


@pytest.mark.parametrize(
    ("names", "options", "message"),
    [
        (["a_depth.png", "b_depth.png"], {}, "view angles are unknown"),
        (["depth_v1.png", "depth_view1.png"], {}, "both station 1 view 1"),
        (["depth_010deg.png", "depth_045deg.png"], {"step_deg": 45.0}, "not a multiple"),
        (["depth.png"], {}, "--intrinsics fx,fy,cx,cy or --calibration"),
    ],
)
def test_what_cannot_be_worked_out_is_refused(tmp_path, names, options, message):
    for name in names:
        _write(tmp_path / "scan" / name, _depth_mm(0))
    intrinsics = None if "intrinsics" in message else INTRINSICS
    with pytest.raises(FieldappError, match=message):
        import_folder(
            tmp_path / "scan", tmp_path / "out", FolderOptions(intrinsics=intrinsics, **options)
        )


def test_bad_intrinsics_are_named(tmp_path):
    _write(tmp_path / "scan" / "depth.png", _depth_mm(0))
    with pytest.raises(FieldappError, match=r"principal point \(90, 24\) inside the 64 x 48"):
        import_folder(tmp_path / "scan", tmp_path / "out", FolderOptions(intrinsics="60,60,90,24"))


def test_a_simulated_session_flattened_and_imported_reads_the_same(tmp_path, capsys):
    """Station 5 views 0-1 of a simulated plot, written as a flat folder of
    scan_s5_v<k>_<kind>.png, imported with the session's calibration.json: the same images,
    the same view step, only station 5 kept."""
    sim = tmp_path / "sim"
    assert main(["simulate", "--out", str(sim), "--stations", "5", "--views", "0,1"]) == 0
    document = json.loads((sim / "session.json").read_text())
    flat = tmp_path / "flat"
    flat.mkdir()
    for capture in document["captures"]:
        for kind in ("depth", "color", "ir"):
            name = f"scan_s{capture['station']}_v{capture['view']}_{kind}.png"
            (flat / name).write_bytes((sim / capture[kind]).read_bytes())
    out = tmp_path / "imported"
    assert main(["import", "folder", str(flat), "--calibration", str(sim / "calibration.json"),
                 "--out", str(out)]) == 0  # fmt: skip
    assert "calibration stations 1, 2, 3, 4, 6, 7, 8, 9 not used" in capsys.readouterr().out
    original, imported = load_session(sim), load_session(out)
    assert imported.missing() == [(5, v) for v in range(2, 8)]
    np.testing.assert_array_equal(
        imported.calibration.view_step.matrix, original.calibration.view_step.matrix
    )
    assert imported.calibration.depth_camera == original.calibration.depth_camera
    for a, b in zip(original.captures, imported.captures, strict=True):
        first, second = original.read_capture(a, True), imported.read_capture(b, True)
        np.testing.assert_array_equal(first.depth_m, second.depth_m)
        np.testing.assert_array_equal(first.color, second.color)
        np.testing.assert_array_equal(first.ir, second.ir)


def test_kind_folders_and_float_depth(tmp_path):
    """TUM RGB-D style: depth/ and rgb/ folders with the same names, depth in 1/5000 m; and
    float depth in metres (.npy), NaN and 0 as missing."""
    tum = tmp_path / "tum"
    for index in range(2):
        _write(tum / "depth" / f"{index:04d}.png", np.full((H, W), 5000 + 100 * index, np.uint16))
        _write(tum / "rgb" / f"{index:04d}.png", np.full((H, W, 3), 90, np.uint8))
    options = FolderOptions(intrinsics=INTRINSICS, depth_scale=5000.0, step_deg=45.0)
    assert import_folder(tum, tmp_path / "a", options).depth_only == 0
    session = load_session(tmp_path / "a")
    depth = session.read_capture(session.captures[1]).depth_m
    assert float(np.nanmedian(depth)) == pytest.approx(1.02)
    floats = tmp_path / "floats"
    floats.mkdir()
    metres = np.full((H, W), 1.25, np.float32)
    metres[0, :2] = (np.nan, 0.0)
    np.save(floats / "depth_v0.npy", metres)
    import_folder(floats, tmp_path / "b", FolderOptions(intrinsics=INTRINSICS))
    session = load_session(tmp_path / "b")
    units = read_depth_units(session.path_of(session.captures[0].depth))
    read = depth_units_to_m(units, session.calibration.depth_camera.depth_scale)
    assert np.isnan(read[0, :2]).all() and float(read[5, 5]) == pytest.approx(1.25)
