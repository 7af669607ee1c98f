"""Issue 23 item 7: bad files give one line naming the file in ``verify`` and ``reconstruct``
alike, never a traceback or a hang."""

from __future__ import annotations

import json
import os
import shutil
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from fieldapp.cli import main

DEPTH = "frames/s05/v0/depth.png"


def copy_of(small_session: Path, tmp_path: Path, checksums: bool = False) -> Path:
    """A copy of the small session; without checksums unless asked, as another tool writes."""
    folder = tmp_path / "session"
    shutil.copytree(small_session, folder)
    if not checksums:
        document = json.loads((folder / "session.json").read_text())
        for capture in document["captures"]:
            capture.pop("sha256", None)
        (folder / "session.json").write_text(json.dumps(document))
    return folder


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(args)
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, err


def verify(folder: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    return run(["verify", str(folder)], capsys)


def reconstruct(folder: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    return run(["reconstruct", str(folder), "--out", str(folder.parent / "out"), "--quiet"], capsys)


def lines_with(text: str, *parts: str) -> list[str]:
    return [line for line in text.splitlines() if all(p in line for p in parts)]


def png_header_only(width: int, height: int, bit_depth: int = 16, colour_type: int = 0) -> bytes:
    """A valid PNG signature and header claiming ``width`` x ``height``, then a tiny IDAT."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\0" * 4096))
        + chunk(b"IEND", b"")
    )


def test_a_png_claiming_100000_squared_pixels_is_refused_before_decoding(
    small_session, tmp_path, capsys, monkeypatch
):
    folder = copy_of(small_session, tmp_path)
    bomb = png_header_only(100_000, 100_000)
    (folder / DEPTH).write_bytes(bomb)
    decoded: list[bytes] = []
    real_imdecode = cv2.imdecode

    def spy(buffer, flags):
        decoded.append(bytes(buffer))
        return real_imdecode(buffer, flags)

    monkeypatch.setattr(cv2, "imdecode", spy)  # images.py imports OpenCV where it decodes
    for command in (verify, reconstruct):
        code, err = command(folder, capsys)
        found = lines_with(err, str(folder / DEPTH), "100000 x 100000")
        assert len(found) == 1, err
        assert code == (1 if command is verify else 0), err
    assert decoded and bomb not in decoded  # the others were decoded, the bomb never


def test_a_symbolic_link_loop_is_one_line(small_session, tmp_path, capsys):
    folder = copy_of(small_session, tmp_path)
    (folder / DEPTH).unlink()
    (folder / DEPTH).symlink_to("depth.png")
    for command in (verify, reconstruct):
        _, err = command(folder, capsys)
        assert len(lines_with(err, str(folder / DEPTH), "symbolic link loop")) == 1, err


def test_a_fifo_in_place_of_a_frame_never_hangs(small_session, tmp_path, capsys):
    folder = copy_of(small_session, tmp_path)
    (folder / DEPTH).unlink()
    os.mkfifo(folder / DEPTH)
    for command in (verify, reconstruct):
        _, err = command(folder, capsys)
        assert len(lines_with(err, str(folder / DEPTH), "FIFO")) == 1, err


@pytest.mark.parametrize("name", ["session.json", "calibration.json"])
def test_a_fifo_in_place_of_a_document_never_hangs(small_session, tmp_path, capsys, name):
    folder = copy_of(small_session, tmp_path)
    (folder / name).unlink()
    os.mkfifo(folder / name)
    for command in (verify, reconstruct):
        code, err = command(folder, capsys)
        assert code == 1
        assert lines_with(err, str(folder / name), "FIFO"), err


def test_a_folder_in_place_of_a_frame(small_session, tmp_path, capsys):
    folder = copy_of(small_session, tmp_path)
    (folder / DEPTH).unlink()
    (folder / DEPTH).mkdir()
    code, err = verify(folder, capsys)
    assert code == 1
    assert lines_with(err, str(folder / DEPTH), "is a folder"), err


def test_a_link_to_a_device_outside_the_folder_is_refused(small_session, tmp_path, capsys):
    folder = copy_of(small_session, tmp_path)
    (folder / DEPTH).unlink()
    (folder / DEPTH).symlink_to("/dev/zero")
    for command in (verify, reconstruct):
        code, err = command(folder, capsys)
        assert code == 1
        assert lines_with(err, "session.json: captures[", "depth: path escapes the folder"), err


def test_devices_and_folders_are_never_read(tmp_path):
    from fieldapp.io.files import UnreadableFile, read_regular_file

    with pytest.raises(UnreadableFile, match="character device"):
        read_regular_file(Path("/dev/zero"), 1 << 20)
    with pytest.raises(UnreadableFile, match="folder"):
        read_regular_file(tmp_path, 1 << 20)
    (tmp_path / "big").write_bytes(b"x" * 101)
    with pytest.raises(UnreadableFile, match="101 bytes, more than a test file can be"):
        read_regular_file(tmp_path / "big", 100, "a test file")
    assert read_regular_file(tmp_path / "big", 101) == b"x" * 101


def test_headers_give_the_size_without_decoding():
    from fieldapp.io.headers import HeaderError, read_header

    colour = np.zeros((37, 53, 3), np.uint8)
    for extension, kind, bits in ((".png", "png", 8), (".jpg", "jpeg", 8)):
        header = read_header(cv2.imencode(extension, colour)[1].tobytes())
        assert (header.format, header.width, header.height, header.channels) == (
            kind,
            53,
            37,
            3,
        )
        assert header.bit_depth == bits
    depth = read_header(cv2.imencode(".png", np.zeros((5, 7), np.uint16))[1].tobytes())
    assert (depth.width, depth.height, depth.channels, depth.bit_depth) == (7, 5, 1, 16)
    for garbage in (b"", b"GIF89a", b"\x89PNG\r\n\x1a\n\0\0", b"\xff\xd8\xff\xe0\0\x10JFIF"):
        with pytest.raises(HeaderError):
            read_header(garbage)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("fx", 1e308, "field of view"),
        ("fy", 0.01, "field of view"),
        ("cx", -5.0, "outside the image"),
        ("cy", 1000.0, "outside the image"),
        ("depth_scale", 1e308, "units per metre"),
        ("depth_scale", 1.0, "units per metre"),
        ("distortion", [5.0, 0, 0, 0, 0], "of the image diagonal"),
        ("distortion", [-0.5, 0.0, 0.0, 0.0, 0.0], "folds the image"),
        ("width", 100_000, "more than"),
    ],
)
def test_physically_impossible_intrinsics_are_named(
    small_session, tmp_path, capsys, field, value, message
):
    folder = copy_of(small_session, tmp_path)
    path = folder / "calibration.json"
    document = json.loads(path.read_text())
    document["depth_camera"][field] = value
    path.write_text(json.dumps(document))
    for command in (verify, reconstruct):
        code, err = command(folder, capsys)
        assert code == 1, err
        assert lines_with(err, f"{path}: depth_camera.{field}:", message), err


@pytest.mark.parametrize("value", [1e12, 1.3407807929942597e154])
def test_an_impossible_rig_translation_is_named(small_session, tmp_path, capsys, value):
    """Also where the translation's squares overflow a float (a property test drew
    1.34e154: the norm warned of an overflow instead of naming the field)."""
    folder = copy_of(small_session, tmp_path)
    path = folder / "calibration.json"
    document = json.loads(path.read_text())
    document["view_step"]["matrix"][0][3] = value
    path.write_text(json.dumps(document))
    code, err = verify(folder, capsys)
    assert code == 1
    assert lines_with(err, f"{path}: view_step.matrix:", "more than a rig can move"), err


def test_json_numbers_out_of_range_and_deep_nesting_are_one_line(small_session, tmp_path, capsys):
    folder = copy_of(small_session, tmp_path)
    path = folder / "session.json"
    text = path.read_text()
    path.write_text(text.replace('"captures"', '"vendor": 1e400, "captures"', 1))
    assert lines_with(verify(folder, capsys)[1], str(path), "out of the range of a number")
    path.write_text("[" * 100_000 + "]" * 100_000)
    assert lines_with(verify(folder, capsys)[1], str(path), "nested too deeply")


def test_a_view_beyond_the_turn_is_named_instead_of_looped_over(small_session, tmp_path, capsys):
    # found by the fuzz test: Eq. 9 applied 10**12 times hung verify and reconstruct
    folder = copy_of(small_session, tmp_path)
    path = folder / "session.json"
    document = json.loads(path.read_text())
    document["captures"][1]["view"] = 10**12
    path.write_text(json.dumps(document))
    for command in (verify, reconstruct):
        code, err = command(folder, capsys)
        assert code == 1
        assert lines_with(err, f"{path}: captures[1].view:", "beyond the 8 views of a turn"), err


def test_a_vanishing_view_step_is_named(small_session, tmp_path, capsys):
    # found by the fuzz test: 1e-9 degrees made 3.6e11 expected views and hung verify
    folder = copy_of(small_session, tmp_path)
    path = folder / "calibration.json"
    document = json.loads(path.read_text())
    document["view_step"]["angle_deg"] = 1e-9
    path.write_text(json.dumps(document))
    for command in (verify, reconstruct):
        code, err = command(folder, capsys)
        assert code == 1
        assert lines_with(err, f"{path}: view_step.angle_deg:", "less than a turntable"), err


def test_an_output_folder_that_is_a_file_is_one_line(small_session, tmp_path, capsys):
    out = tmp_path / "out"
    out.write_text("not a folder")
    code, err = run(["reconstruct", str(small_session), "--out", str(out), "--quiet"], capsys)
    assert code == 1
    assert lines_with(err, f"{out}: cannot write the results"), err
