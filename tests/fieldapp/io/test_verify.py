"""``fieldapp verify``: accepts spec-compliant sessions from other tools, names every problem."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from fieldapp.cli import main
from fieldapp.errors import FormatError
from fieldapp.io.session import load_session
from fieldapp.verify import verify_session


def run_verify(folder: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(["verify", str(folder)])
    out, err = capsys.readouterr()
    return code, out, err


def test_accepts_a_session_written_by_another_tool(make_spec_session, capsys):
    folder = make_spec_session()
    code, out, err = run_verify(folder, capsys)
    assert code == 0, err
    assert "8 captures, 2 stations" in out
    assert "no missing captures" in out
    assert err == ""


def test_reports_missing_captures_but_stays_usable(make_spec_session, capsys):
    folder = make_spec_session(skip=((2, 3), (1, 0)))
    code, out, _ = run_verify(folder, capsys)
    assert code == 0
    assert "missing captures (2): s1 v0, s2 v3" in out


def test_a_frame_folder_named_by_its_time_is_a_relative_path(make_spec_session, capsys):
    """A colon makes a Windows drive only as the second character (``C:``): a folder named
    ``2026-12-06T02:22:04`` is one of the spec's free paths."""
    folder = make_spec_session()
    (folder / "data").rename(folder / "2026-12-06T02:22:04")
    path = _session_json(folder)
    path.write_text(path.read_text().replace('"data/', '"2026-12-06T02:22:04/'))
    code, out, err = run_verify(folder, capsys)
    assert code == 0, err
    assert "8 captures, 2 stations" in out


def test_a_captured_station_without_its_calibration_is_named(make_spec_session, edit_json, capsys):
    folder = make_spec_session()
    reference = json.loads(_calibration_json(folder).read_text())["stations"]["reference"]
    other = 1 if reference == 2 else 2
    edit_json(_calibration_json(folder), lambda d: d["stations"]["to_reference"].pop(str(other)))
    code, out, _ = run_verify(folder, capsys)
    assert code == 0  # valid; only a reconstruction needs it
    assert f"calibration.json: stations.to_reference has no entry for station(s) {other}" in out


def _session_json(folder: Path) -> Path:
    return folder / "session.json"


def _calibration_json(folder: Path) -> Path:
    return folder / "calibration.json"


def _break_malformed_json(folder, edit_json):
    _session_json(folder).write_text('{"format": "fieldapp-session/1", "captures": [')


def _break_format(folder, edit_json):
    edit_json(_session_json(folder), lambda d: d.update(format="fieldapp-session/2"))


def _break_missing_field(folder, edit_json):
    edit_json(_session_json(folder), lambda d: d["captures"][2].pop("depth"))


def _break_escaping_path(folder, edit_json):
    edit_json(_session_json(folder), lambda d: d["captures"][0].update(depth="../../etc/passwd"))


def _break_absolute_path(folder, edit_json):
    edit_json(_session_json(folder), lambda d: d["captures"][0].update(color="/etc/hostname"))


def _break_missing_png(folder, edit_json):
    (folder / "data" / "st1_v2_d.png").unlink()


def _break_truncated_png(folder, edit_json):
    path = folder / "data" / "st2_v0_d.png"
    path.write_bytes(path.read_bytes()[:200])


def _break_8bit_depth(folder, edit_json):
    cv2.imwrite(str(folder / "data" / "st1_v3_d.png"), np.full((48, 64), 7, np.uint8))


def _break_rgb_depth(folder, edit_json):
    cv2.imwrite(str(folder / "data" / "st1_v3_d.png"), np.full((48, 64, 3), 7, np.uint16))


def _break_color_size(folder, edit_json):
    cv2.imwrite(str(folder / "data" / "st2_v2_c.png"), np.zeros((40, 64, 3), np.uint8))


def _break_depth_size(folder, edit_json):
    cv2.imwrite(str(folder / "data" / "st2_v2_d.png"), np.zeros((48, 60), np.uint16))


def _break_nan_matrix(folder, edit_json):
    edit_json(_calibration_json(folder), lambda d: d["view_step"]["matrix"][0].__setitem__(3, "X"))
    path = _calibration_json(folder)
    path.write_text(path.read_text().replace('"X"', "NaN"))


def _break_non_rigid(folder, edit_json):
    def stretch(d):
        d["stations"]["to_reference"]["1"][0][0] = 1.2

    edit_json(_calibration_json(folder), stretch)


def _break_reflection(folder, edit_json):
    def flip(d):
        d["ground"]["matrix"][2][2] = -d["ground"]["matrix"][2][2]

    edit_json(_calibration_json(folder), flip)


def _break_last_row(folder, edit_json):
    edit_json(_calibration_json(folder), lambda d: d["view_step"]["matrix"][3].__setitem__(0, 0.5))


def _break_duplicate(folder, edit_json):
    edit_json(_session_json(folder), lambda d: d["captures"].append(dict(d["captures"][1])))


def _break_empty(folder, edit_json):
    edit_json(_session_json(folder), lambda d: d.update(captures=[]))


def test_a_session_without_captures_yet_is_valid_and_says_so(make_spec_session, edit_json, capsys):
    """The spec: "A session may lack captures (an interrupted mission)"; only a reconstruction
    needs some."""
    folder = make_spec_session()
    _break_empty(folder, edit_json)
    code, out, err = run_verify(folder, capsys)
    assert code == 0, err
    assert "no captures yet (an interrupted mission?): nothing to reconstruct" in out
    with pytest.raises(FormatError, match="session has no captures"):
        load_session(folder)  # what a reconstruction reads


def _break_station_type(folder, edit_json):
    edit_json(_session_json(folder), lambda d: d["captures"][4].update(station="one"))


def _break_calibration_missing(folder, edit_json):
    _calibration_json(folder).unlink()


BROKEN = [
    (_break_malformed_json, "session.json: line 1 column", "malformed JSON"),
    (_break_format, "session.json: format", "fieldapp-session/1"),
    (_break_missing_field, "session.json: captures[2].depth", "required"),
    (_break_escaping_path, "session.json: captures[0].depth", "escapes the session folder"),
    (_break_absolute_path, "session.json: captures[0].color", "must be relative"),
    (_break_missing_png, "st1_v2_d.png: depth", "file is missing"),
    (_break_truncated_png, "st2_v0_d.png: depth", "not a decodable image"),
    (_break_8bit_depth, "st1_v3_d.png: depth", "must be 16-bit"),
    (_break_rgb_depth, "st1_v3_d.png: depth", "single-channel"),
    (_break_color_size, "st2_v2_c.png: color", "differs from the depth camera"),
    (_break_depth_size, "st2_v2_d.png: depth", "differs from the calibration"),
    (_break_nan_matrix, "calibration.json", "NaN is not a JSON number"),
    (_break_non_rigid, "calibration.json: stations.to_reference.1", "not orthonormal"),
    (_break_reflection, "calibration.json: ground.matrix", "determinant"),
    (_break_last_row, "calibration.json: view_step.matrix", "last row"),
    (_break_duplicate, "session.json: captures[8]", "already captured by captures[1]"),
    (_break_station_type, "session.json: captures[4].station", "integer"),
    (_break_calibration_missing, "calibration.json", "file is missing"),
]


@pytest.mark.parametrize(
    ("breaker", "where", "what"), BROKEN, ids=lambda x: getattr(x, "__name__", "")
)
def test_rejects_each_broken_variant_naming_file_and_field(
    breaker, where, what, make_spec_session, edit_json, capsys
):
    folder = make_spec_session()
    breaker(folder, edit_json)
    code, _, err = run_verify(folder, capsys)
    assert code != 0
    problem_lines = [line for line in err.splitlines() if line.startswith("problem: ")]
    assert problem_lines, err
    assert any(where in line and what in line for line in problem_lines), err
    assert "Traceback" not in err


def test_reports_every_problem_not_just_the_first(make_spec_session, edit_json):
    folder = make_spec_session()
    _break_missing_png(folder, edit_json)
    _break_color_size(folder, edit_json)
    report = verify_session(folder)
    assert not report.usable
    assert len(report.problems) == 2


def test_not_a_folder(tmp_path, capsys):
    code, _, err = run_verify(tmp_path / "nowhere", capsys)
    assert code == 1
    assert "no such folder" in err


def test_control_characters_in_a_path(make_spec_session, edit_json, capsys):
    folder = make_spec_session()
    edit_json(folder / "session.json", lambda d: d["captures"][3].update(depth="data/a\x00b.png"))
    code, _, err = run_verify(folder, capsys)
    assert code == 1
    assert "captures[3].depth" in err and "control characters" in err
