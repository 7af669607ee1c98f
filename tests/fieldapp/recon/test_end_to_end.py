"""The whole method on a simulated plot, against the simulator's truth."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from devices.geometry import invert, pose_error
from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.recon.outputs import CSV_COLUMNS, GRID_COLUMNS, read_ply
from fieldapp.recon.pipeline import NothingUsable, reconstruct, run_reconstruction
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.settings import ReconstructionSettings

from .conftest import Simulated

pytestmark = pytest.mark.slow  # one simulated session for the module, a few full runs

MATCH_RADIUS_M = 0.12
"""A plant is matched to the truth within this distance: the field frame rests on the nominal
ground matrix, and the real reference station stood a few cm and about a degree off it."""


def truth_xy(plant: dict, frame: str) -> tuple[float, float]:
    """Where the reconstruction should report ``plant``: the map frame when it reports in it."""
    if frame == "map":
        return plant["map_x_m"], plant["map_y_m"]
    return plant["x_m"], plant["y_m"]


def matched_errors(result: Reconstruction, truth: dict) -> dict[str, np.ndarray]:
    """Per true plant, the reconstructed plant nearest to it (each used once)."""
    found = np.array([[p.traits.x_m, p.traits.y_m] for p in result.plants])
    rows = {"dh_cm": [], "dw_cm": [], "h_cm": [], "w_cm": [], "xy": [], "true_xy": []}
    used: set[int] = set()
    for plant in truth["plants"]:
        distance = np.hypot(*(found - truth_xy(plant, result.frame)).T)
        index = int(np.argmin(distance))
        assert distance[index] < MATCH_RADIUS_M, f"{plant['name']} not found"
        assert index not in used, f"{plant['name']} shares plant {index + 1} with another"
        used.add(index)
        traits = result.plants[index].traits
        rows["dh_cm"].append(traits.height_m * 100 - plant["height_cm"])
        rows["dw_cm"].append(traits.width_m * 100 - plant["width_cm"])
        rows["h_cm"].append(plant["height_cm"])
        rows["w_cm"].append(plant["width_cm"])
        rows["xy"].append(found[index])
        rows["true_xy"].append(list(truth_xy(plant, result.frame)))
    return {k: np.array(v) for k, v in rows.items()}


def test_every_plant_is_found_and_none_is_invented(
    reconstruction: Reconstruction, plot_session: Simulated
) -> None:
    matched_errors(reconstruction, plot_session.truth)
    assert len(reconstruction.plants) == len(plot_session.truth["plants"])
    assert [p.id for p in reconstruction.plants] == list(range(1, 17))


def test_heights_and_widths_beat_the_paper(
    reconstruction: Reconstruction, plot_session: Simulated
) -> None:
    e = matched_errors(reconstruction, plot_session.truth)
    assert np.sqrt(np.mean(e["dh_cm"] ** 2)) <= 1.0
    assert np.mean(np.abs(e["dh_cm"]) / e["h_cm"]) <= 0.015
    assert np.sqrt(np.mean(e["dw_cm"] ** 2)) <= 1.2
    assert np.mean(np.abs(e["dw_cm"]) / e["w_cm"]) <= 0.020


def test_plant_positions_are_right_relative_to_each_other(
    reconstruction: Reconstruction, plot_session: Simulated
) -> None:
    e = matched_errors(reconstruction, plot_session.truth)
    found, true = e["xy"] - e["xy"].mean(0), e["true_xy"] - e["true_xy"].mean(0)
    u, _, vt = np.linalg.svd(found.T @ true)
    residual = np.hypot(*(found @ (u @ vt) - true).T)
    assert residual.max() < 0.03  # the stem's foot, within 3 cm once the frames are aligned


def _station_errors(result: Reconstruction, truth: dict) -> dict[int, tuple[float, float]]:
    T = {int(s): np.array(m) for s, m in truth["T_field_camera"].items()}
    reference = result.reference
    return {
        s: pose_error(result.T_reference_station(s), invert(T[reference]) @ T[s])
        for s in result.registrations
    }


def test_every_station_is_registered_within_5_mm_and_0_2_degrees(
    reconstruction: Reconstruction, plot_session: Simulated
) -> None:
    errors = _station_errors(reconstruction, plot_session.truth)
    assert sorted(errors) == list(range(1, 10))
    for station, (translation_m, rotation_deg) in errors.items():
        assert translation_m < 0.005 and rotation_deg < 0.2, (station, translation_m, rotation_deg)
    assert all(r.accepted for r in reconstruction.registrations.values())
    assert not reconstruction.warnings


def test_rejected_refinements_keep_the_coarse_poses_and_are_visibly_worse(
    reconstruction: Reconstruction, plot_session: Simulated
) -> None:
    settings = ReconstructionSettings()
    settings.registration.arrival_sigma_m = 1e-4  # a base believed to stop within 0.1 mm:
    settings.registration.arrival_sigma_deg = 1e-3  # every correction is "implausible"
    coarse = run_reconstruction(load_session(plot_session.folder), settings)
    kept = [w for w in coarse.warnings if "coarse pose kept" in w]
    assert len(kept) == 8
    # the rest: plants drawn twice by misplaced stations overlap and are flagged (the copies
    # meet each other, one may stand off the planting grid, the grid fitted to the stems may
    # be moved)
    assert all(
        w.startswith(("plant ", "plants that may be wider", "planting grid fitted to"))
        or "off the planting grid" in w
        for w in coarse.warnings
        if w not in kept
    )
    assert coarse.plants  # still a result
    errors = _station_errors(coarse, plot_session.truth)
    assert max(t for t, _ in errors.values()) > 0.02  # centimetres off, not millimetres
    fine = _station_errors(reconstruction, plot_session.truth)
    assert max(t for t, _ in errors.values()) > 5 * max(t for t, _ in fine.values())


def test_progress_is_monotonic_and_closing_cancels(plot_session: Simulated) -> None:
    session = load_session(plot_session.folder)
    steps = reconstruct(session, ReconstructionSettings())
    first = next(steps)
    second = next(steps)
    assert first.stage == "local reconstruction" and 0 < first.fraction <= second.fraction < 1
    steps.close()  # cancelled between stations: nothing else runs
    with pytest.raises(StopIteration):
        next(steps)


def _damaged_copy(source: Path, target: Path) -> None:
    shutil.copytree(source, target)
    document = json.loads((target / "session.json").read_text())
    document["captures"] = [c for c in document["captures"] if c["station"] != 9]
    (target / "session.json").write_text(json.dumps(document))
    (target / "frames" / "s01" / "v3" / "depth.png").write_bytes(b"not a png")


def test_cli_on_a_session_with_missing_captures_writes_results_and_warns(
    plot_session: Simulated, tmp_path: Path
) -> None:
    """The command as a user runs it, its output piped: each warning said once (the pipeline's
    log of them printed every one a second time), no progress bar's leftovers."""
    damaged = tmp_path / "damaged"
    _damaged_copy(plot_session.folder, damaged)
    out = tmp_path / "out"
    command = [sys.executable, "-m", "fieldapp", "reconstruct", str(damaged), "--out", str(out)]
    done = subprocess.run(command, capture_output=True, text=True)  # pytest-timeout: a hang
    assert done.returncode == 0, done.stderr[-2000:]
    assert "" not in done.stdout.splitlines(), done.stdout  # no progress bar into a pipe
    assert done.stderr.count("8 captures missing: s9 v0") == 1, done.stderr
    assert done.stderr.count("station 1 view 3 skipped") == 1, done.stderr

    lines = (out / "plants.csv").read_text().splitlines()
    # the simulated session carries its plan's planting grid: each plant's row and column
    assert lines[0] == ",".join([*CSV_COLUMNS, *GRID_COLUMNS])
    assert lines[0].startswith("plant,x_m,y_m,height_cm,width_cm,points,")
    assert len(lines) - 1 >= 15  # the corner plant seen mostly from station 9 may be lost
    report = json.loads((out / "report.json").read_text())
    assert sorted(report["stations"]) == [str(s) for s in range(1, 9)]
    assert {"icp_fitness", "icp_rmse_m", "correction", "T_field_station"} <= set(
        report["stations"]["1"]
    )
    assert list(report["points_kept"])[:4] == [
        "measured_pixels",
        "excess_green",
        "pass_through",
        "voxel_mean",
    ]
    assert set(report["timings_s"]) >= {"local reconstruction", "registration", "plants"}
    cloud = read_ply(out / "cloud.ply")
    plant_files = sorted((out / "plants").glob("*.ply"))
    assert len(plant_files) == len(lines) - 1
    first = lines[1].split(",")
    assert len(read_ply(out / "plants" / f"{first[0]}.ply")) == int(first[5])
    assert len(cloud) >= sum(len(read_ply(p)) for p in plant_files)


def test_open3d_reads_the_clouds(reconstruction: Reconstruction, tmp_path: Path) -> None:
    import open3d as o3d

    from fieldapp.recon.outputs import write_outputs

    write_outputs(
        tmp_path,
        reconstruction.rows(),
        reconstruction.cloud,
        {p.id: p.cloud for p in reconstruction.plants},
        reconstruction.report(),
    )
    cloud = o3d.io.read_point_cloud(str(tmp_path / "cloud.ply"))
    assert len(cloud.points) == len(reconstruction.cloud)
    np.testing.assert_allclose(np.asarray(cloud.points), reconstruction.cloud.points, atol=1e-6)
    np.testing.assert_allclose(
        np.asarray(cloud.colors) * 255, reconstruction.cloud.colors, atol=0.5
    )


def test_nothing_usable_is_one_clear_line(
    plot_session: Simulated, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    empty = tmp_path / "unreadable"
    shutil.copytree(plot_session.folder, empty, ignore=shutil.ignore_patterns("*.png"))
    with pytest.raises(NothingUsable, match="no capture could be read"):
        run_reconstruction(load_session(empty), ReconstructionSettings())
    assert main(["reconstruct", str(empty), "--out", str(tmp_path / "out"), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("fieldapp reconstruct: ") and "no capture could be read" in err[-1]
    # and why, with the first file named: the run ends before its warnings are printed
    assert "station 1 view 0 skipped: " in err[-1] and "s01/v0/depth.png" in err[-1]
    assert err[-1].endswith(f"and {len(plot_session.truth['captures']) - 2} more")
    assert not (tmp_path / "out").exists()


def test_without_a_ground_matrix_plants_are_still_in_the_map_frame(
    plot_session: Simulated, tmp_path: Path
) -> None:
    """The field frame then rests on the reference camera, but the base poses place the plot
    on the map (session-format spec: the field frame's x and y are the map's)."""
    folder = tmp_path / "no-ground"
    shutil.copytree(plot_session.folder, folder)
    calibration = json.loads((folder / "calibration.json").read_text())
    del calibration["ground"]
    (folder / "calibration.json").write_text(json.dumps(calibration))
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    assert result.frame == "map"
    e = matched_errors(result, plot_session.truth)
    assert len(result.plants) == 16
    assert np.max(np.hypot(*(e["xy"] - e["true_xy"]).T)) < 0.03  # absolute, on the map
    assert np.sqrt(np.mean(e["dh_cm"] ** 2)) <= 1.0
    assert np.sqrt(np.mean(e["dw_cm"] ** 2)) <= 1.2


def test_without_map_poses_plants_stay_in_the_field_frame(
    plot_session: Simulated, tmp_path: Path
) -> None:
    folder = tmp_path / "no-poses"
    shutil.copytree(plot_session.folder, folder)
    document = json.loads((folder / "session.json").read_text())
    for capture in document["captures"]:
        del capture["base_pose"]
    del document["plan"]  # its stations' map poses would place the plot too
    (folder / "session.json").write_text(json.dumps(document))
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    assert result.frame == "field" and result.report()["T_map_field"] is None
    assert len(matched_errors(result, plot_session.truth)["xy"]) == 16
