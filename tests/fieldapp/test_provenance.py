"""Provenance of every result (devices, calibration, software, settings hash) in report.json,
provenance.json, report.html and the results database; ``fieldapp reconstruct`` never
overwrites results unless told to."""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fieldapp import __version__, provenance
from fieldapp.cli import main
from fieldapp.evaluate.report import ReportInputs, build_report
from fieldapp.io.session import load_session
from fieldapp.provenance import provenance_of, summary_line
from fieldapp.recon.outputs import CSV_COLUMNS
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.db import ResultsDB
from fieldapp.results.sources import settings_hash
from fieldapp.settings import load_settings


@pytest.fixture(scope="module")
def settings_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("settings") / "settings.yaml"
    path.write_text("reconstruction:\n  threads: 1\n", encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def simulated_results(small_session: Path, settings_file: Path, tmp_path_factory) -> Path:
    """``fieldapp reconstruct`` of the simulated session the ``small_session`` fixture was cut
    from (stations 4 and 5, views 0 and 1, full resolution: about 1.5 s of CPU)."""
    session = small_session.parent / "full"  # written by `fieldapp simulate`
    out = tmp_path_factory.mktemp("simulated") / "results"
    args = ["reconstruct", str(session), "--out", str(out), "--settings", str(settings_file)]
    assert main([*args, "--quiet"]) == 0
    return out


@pytest.fixture(scope="module")
def imported_results(small_session: Path, settings_file: Path, tmp_path_factory) -> Path:
    """``small_session`` flattened into a folder of images, brought in by ``fieldapp import
    folder`` with its calibration file, then reconstructed."""
    root = tmp_path_factory.mktemp("imported")
    document = json.loads((small_session / "session.json").read_text())
    (root / "flat").mkdir()
    for capture in document["captures"]:
        for kind in ("depth", "color", "ir"):
            name = f"scan_s{capture['station']}_v{capture['view']}_{kind}.png"
            shutil.copyfile(small_session / capture[kind], root / "flat" / name)
    calibration = str(small_session / "calibration.json")
    args = ["import", "folder", str(root / "flat"), "--calibration", calibration]
    assert main([*args, "--out", str(root / "session")]) == 0
    args = ["reconstruct", str(root / "session"), "--out", str(root / "results")]
    assert main([*args, "--settings", str(settings_file), "--quiet"]) == 0
    return root / "results"


def _report(results: Path) -> dict:
    return json.loads((results / "report.json").read_text())


def _expected_settings(settings_file: Path) -> dict:
    return load_settings(settings_file).reconstruction.model_dump(mode="json")


def test_a_simulated_session_says_so_everywhere(simulated_results, settings_file, tmp_path):
    report = _report(simulated_results)
    document = report["provenance"]
    session_folder = Path(document["session"]["folder"])
    assert document["source"]["kind"] == "simulated"
    assert document["source"]["simulated"]["seed"] == 3
    calibration = document["calibration"]
    assert calibration["kind"] == "nominal" and calibration["date"] is None
    digest = hashlib.sha256((session_folder / "calibration.json").read_bytes()).hexdigest()
    assert calibration["sha256"] == digest
    assert calibration["sections"]["depth_camera"] == "nominal"
    assert document["software"]["version"] == report["software_version"] == __version__
    assert report["settings"] == _expected_settings(settings_file)
    assert document["settings_sha256"] == settings_hash(_expected_settings(settings_file))
    # the CSVs keep the spec's first line; the provenance is beside them
    header = (simulated_results / "plants.csv").read_text().splitlines()[0]
    assert header.split(",")[: len(CSV_COLUMNS)] == CSV_COLUMNS
    assert (simulated_results / "leaves.csv").read_text().startswith("plant_id,leaf_id,")
    assert json.loads((simulated_results / "provenance.json").read_text()) == document
    html = build_report(simulated_results, ReportInputs())
    line = summary_line(document)
    assert line.startswith("Simulated devices · calibration: nominal (sha256 " + digest[:8])
    assert document["settings_sha256"][:8] in line and line in html
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        run_id = db.record_run("plot", session_folder, simulated_results)
        (run,) = db.runs()
        assert run.provenance == document
        assert run.settings_sha256 == document["settings_sha256"]  # the report's settings
        row = db.connection.execute(
            "SELECT source, calibration_sha256 FROM runs WHERE id = ?", (run_id,)
        ).fetchone()
        assert tuple(row) == ("simulated", digest)


def test_an_imported_session_says_so_everywhere(imported_results, tmp_path):
    document = _report(imported_results)["provenance"]
    assert document["source"]["kind"] == "imported"
    assert document["source"]["imported"]["by"] == "folder"
    flat = (imported_results.parent / "flat").resolve()
    assert Path(document["source"]["imported"]["from"]) == flat
    assert json.loads((imported_results / "provenance.json").read_text()) == document
    html = build_report(imported_results, ReportInputs())
    assert summary_line(document).startswith("Imported data · calibration: nominal") and (
        summary_line(document) in html
    )
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        db.record_run("plot", Path(document["session"]["folder"]), imported_results)
        assert db.runs()[0].provenance == document


def test_results_without_provenance_say_unknown(imported_results, tmp_path):
    old = tmp_path / "old"
    shutil.copytree(imported_results, old)
    (old / "provenance.json").unlink()
    report = _report(old)
    del report["provenance"]
    (old / "report.json").write_text(json.dumps(report))
    assert "Provenance unknown" in build_report(old, ReportInputs())
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        db.record_run("plot", None, old, date=dt.date(2026, 6, 1))
        assert db.runs()[0].provenance is None


def test_the_settings_hash_follows_the_settings_and_nothing_else(small_session):
    session = load_session(small_session)
    default = provenance_of(session, ReconstructionSettings()).document["settings_sha256"]
    again = provenance_of(session, ReconstructionSettings()).document["settings_sha256"]
    assert again == default  # another call, another time stamp: the same hash
    changed = ReconstructionSettings()
    changed.crop.radius_m = 2.0
    assert provenance_of(session, changed).document["settings_sha256"] != default
    dumped = ReconstructionSettings().model_dump(mode="json")
    reordered = dict(reversed(list(dumped.items())))
    assert provenance_of(session, reordered).document["settings_sha256"] == default


def test_a_calibrated_section_gives_its_date(small_session, tmp_path):
    folder = tmp_path / "session"
    shutil.copytree(small_session, folder)
    calibration = json.loads((folder / "calibration.json").read_text())
    calibration["depth_camera"]["calibrated"] = {"date": "2026-11-30T10:00:00+00:00"}
    (folder / "calibration.json").write_text(json.dumps(calibration))
    document = provenance_of(load_session(folder), ReconstructionSettings()).document
    assert document["source"]["kind"] == "unknown"  # written by SessionWriter without a word
    assert document["calibration"]["kind"] == "partly calibrated"
    assert document["calibration"]["date"].startswith("2026-11-30")
    assert "calibration: partly calibrated 2026-11-30 (sha256" in summary_line(document)


def test_no_git_no_commit_and_no_failure(monkeypatch):
    def absent(*args, **kwargs):
        raise FileNotFoundError("git")

    monkeypatch.setattr(subprocess, "run", absent)
    provenance.software.cache_clear()
    try:
        found = provenance.software()
    finally:
        provenance.software.cache_clear()
    assert found == {"name": "fieldapp", "version": __version__, "commit": None, "modified": None}


@pytest.mark.parametrize(
    ("line", "commit", "modified"),
    [
        ("commit 0123456789ab", "0123456789ab", False),
        ("commit 0123456789ab modified", "0123456789ab", True),
        ("commit unknown", None, None),
    ],
)
def test_the_bundle_names_the_commit_it_was_built_from(
    monkeypatch, tmp_path, line, commit, modified
):
    """A bundle has no git checkout beside it; packaging/build.sh writes the commit into
    BUILD-INFO beside the executable, and each result's provenance names it."""
    (tmp_path / "BUILD-INFO").write_text(f"fieldapp 0.1.0, built today on Linux x86_64\n{line}\n")
    monkeypatch.setattr(sys, "frozen", True, raising=False)
    monkeypatch.setattr(sys, "executable", str(tmp_path / "fieldapp"))
    provenance.software.cache_clear()
    try:
        found = provenance.software()
    finally:
        provenance.software.cache_clear()
    assert (found["commit"], found["modified"]) == (commit, modified)
    assert provenance.bundle_commit(tmp_path / "absent") == (None, None)


def test_reconstruct_refuses_to_overwrite_results(small_session, tmp_path, capsys):
    out = tmp_path / "results"
    args = ["reconstruct", str(small_session), "--out", str(out), "--quiet"]
    assert main(args) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "already holds results" in err[0] and "--overwrite" in err[0]
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    (out / "report.json").write_text("{}")  # so a replaced report can be told from the old
    assert main([*args, "--overwrite"]) == 0
    assert _report(out)["provenance"]["session"]["id"] == load_session(small_session).id


@pytest.mark.parametrize(
    ("devices", "kind"),
    [
        ({}, "simulated"),
        ({"table_port": "/dev/ttyUSB0"}, "mixed"),
        (
            {"camera_backend": "kinect2", "table_port": "/dev/ttyUSB0", "base_endpoint": "tcp://b"},
            "real",
        ),
    ],
)
def test_a_mission_session_names_its_devices_and_rig_file(small_session, tmp_path, devices, kind):
    from fieldapp.mission.folder import PLAN_FILE
    from fieldapp.mission.plan import default_plan, save_plan
    from fieldapp.settings import DeviceSettings

    folder = tmp_path / "mission"
    shutil.copytree(small_session, folder)
    document = json.loads((folder / "session.json").read_text())
    (folder / "session.json").write_text(json.dumps(document | {"mission": "north"}))
    rig_file = tmp_path / "rig-calibration.json"
    shutil.copyfile(folder / "calibration.json", rig_file)
    plan = default_plan(DeviceSettings(**devices)).model_copy(update={"calibration": rig_file})
    save_plan(plan, folder / PLAN_FILE)
    found = provenance_of(load_session(folder), ReconstructionSettings()).document
    assert found["source"]["kind"] == kind
    assert found["source"]["devices"]["table"] == devices.get("table_port", "simulated")
    rig = found["calibration"]["rig_file"]
    assert rig["path"] == str(rig_file) and rig["same"] is True
    assert rig["sha256"] == hashlib.sha256(rig_file.read_bytes()).hexdigest()
    rig_file.write_text(rig_file.read_text().replace('"reference": 5', '"reference": 4'))
    changed = provenance_of(load_session(folder), ReconstructionSettings()).document
    assert changed["calibration"]["rig_file"]["same"] is False


def test_a_new_run_without_organs_removes_the_earlier_leaves(tmp_path):
    from fieldapp.provenance import RunProvenance
    from fieldapp.recon.cloud import Cloud
    from fieldapp.recon.outputs import LeafRow, PlantRow, write_outputs

    cloud = Cloud(np.zeros((3, 3)), np.zeros((3, 3), np.uint8))
    rows = [PlantRow(1, 0.0, 0.0, 10.0, 5.0, 3)]
    leaves = [LeafRow(1, 1, 10.0, 2.0, 15.0, 40.0, 90.0, 3.0)]
    write_outputs(tmp_path, rows, cloud, {1: cloud}, {}, leaves=leaves)
    write_outputs(tmp_path, rows, cloud, {1: cloud}, {})  # a re-export keeps them
    assert (tmp_path / "leaves.csv").is_file()
    run = RunProvenance({"software": {"version": "0.1.0"}}, {"threads": 1})
    write_outputs(tmp_path, rows, cloud, {1: cloud}, {}, provenance=run)
    assert not (tmp_path / "leaves.csv").exists()
    assert _report(tmp_path)["settings"] == {"threads": 1}
