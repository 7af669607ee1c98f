"""``sha256`` per capture file: written by the writer, checked by every reader."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import pytest

from fieldapp.io.session import load_session
from fieldapp.verify import verify_session

from .test_bad_files import DEPTH, copy_of, lines_with, reconstruct, verify


def test_the_writer_records_the_sha256_of_every_file(small_session):
    session = load_session(small_session)
    assert len(session.captures) == 4
    for capture in session.captures:
        assert capture.sha256 is not None
        assert set(capture.sha256) == {"depth", "color", "ir"}
        for name, relative in capture.files().items():
            digest = hashlib.sha256((small_session / relative).read_bytes()).hexdigest()
            assert capture.sha256[name] == digest


def _re_encode(path: Path) -> None:
    """Same pixels, different bytes: the file still decodes to the same image."""
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    before = path.read_bytes()
    cv2.imwrite(str(path), image, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    assert path.read_bytes() != before
    assert (cv2.imread(str(path), cv2.IMREAD_UNCHANGED) == image).all()


def test_a_file_that_still_decodes_but_changed_is_reported_damaged(small_session, tmp_path, capsys):
    folder = copy_of(small_session, tmp_path, checksums=True)
    _re_encode(folder / DEPTH)
    code, err = verify(folder, capsys)
    assert code == 1
    assert len(lines_with(err, "problem:", str(folder / DEPTH), "depth: damaged")) == 1, err
    assert len(lines_with(err, "problem:")) == 1, err
    code, err = reconstruct(folder, capsys)
    assert code == 0
    assert lines_with(err, "warning: station 5 view 0 skipped", "damaged"), err


def test_checksums_are_case_insensitive_and_optional(small_session, tmp_path):
    folder = copy_of(small_session, tmp_path, checksums=True)
    path = folder / "session.json"
    document = json.loads(path.read_text())
    document["captures"][0]["sha256"] = {
        k: v.upper() for k, v in document["captures"][0]["sha256"].items()
    }
    del document["captures"][1]["sha256"]
    path.write_text(json.dumps(document))
    assert verify_session(folder).usable


@pytest.mark.parametrize(
    ("sha256", "field", "message"),
    [
        ({"depth": "abc"}, "captures[0].sha256.depth", "should match pattern"),
        ({"depth": 5}, "captures[0].sha256.depth", "string"),
        ("deadbeef", "captures[0].sha256", "dictionary"),
    ],
)
def test_malformed_checksums_are_named(small_session, tmp_path, sha256, field, message):
    folder = copy_of(small_session, tmp_path)
    path = folder / "session.json"
    document = json.loads(path.read_text())
    document["captures"][0]["sha256"] = sha256
    path.write_text(json.dumps(document))
    report = verify_session(folder)
    assert any(p.field == field and message in p.message for p in report.problems), report.problems


def test_a_checksum_for_a_file_the_capture_lacks_is_named(small_session, tmp_path):
    folder = copy_of(small_session, tmp_path, checksums=True)
    path = folder / "session.json"
    document = json.loads(path.read_text())
    del document["captures"][2]["ir"]
    path.write_text(json.dumps(document))
    report = verify_session(folder)
    assert [(p.field, p.message) for p in report.problems] == [
        ("captures[2].sha256.ir", "names no file")
    ]


def test_a_depth_only_capture_verifies(small_session, tmp_path):
    folder = copy_of(small_session, tmp_path)
    path = folder / "session.json"
    document = json.loads(path.read_text())
    del document["captures"][1]["color"]
    path.write_text(json.dumps(document))
    report = verify_session(folder)
    assert report.usable, report.problems
