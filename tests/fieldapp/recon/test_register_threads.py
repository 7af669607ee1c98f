"""The same session gives the same results for any thread count (issue 19)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fieldapp.io.session import load_session
from fieldapp.recon.early import start_reading
from fieldapp.recon.outputs import write_outputs
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.settings import ReconstructionSettings

from .conftest import Simulated

pytestmark = pytest.mark.slow  # one more reconstruction of the standard plot


def _write(result: Reconstruction, folder: Path) -> tuple[bytes, dict]:
    plants = {p.id: p.cloud for p in result.plants}
    write_outputs(
        folder, result.rows(), result.cloud, plants, result.report(), **result.output_extras()
    )
    report = json.loads((folder / "report.json").read_text())
    for measured in ("timings_s", "cpu_s"):  # wall and CPU seconds differ from run to run
        assert report.pop(measured)
    return (folder / "plants.csv").read_bytes(), report


def test_one_and_two_threads_give_identical_outputs(
    reconstruction: Reconstruction, plot_session: Simulated, tmp_path: Path
) -> None:
    assert ReconstructionSettings().threads == 2  # the session fixture ran with two
    single = run_reconstruction(
        load_session(plot_session.folder), ReconstructionSettings(threads=1)
    )
    csv_two, report_two = _write(reconstruction, tmp_path / "two")
    csv_one, report_one = _write(single, tmp_path / "one")
    assert csv_one == csv_two
    assert report_one == report_two
    assert (tmp_path / "one" / "cloud.ply").read_bytes() == (
        tmp_path / "two" / "cloud.ply"
    ).read_bytes()
    assert repr(single.organs) == repr(reconstruction.organs)  # two: half in a forked worker
    verdicts = {s["verdict"] for s in report_one["stations"].values()}
    assert verdicts == {"reference", "refined"}
    assert all(s["uncertainty_mm"] is not None for s in report_one["stations"].values())


def test_stations_read_by_the_early_reader_give_identical_outputs(
    reconstruction: Reconstruction, plot_session: Simulated, tmp_path: Path
) -> None:
    """``fieldapp reconstruct``'s path: a reader forked before the pipeline starts."""
    session, settings = load_session(plot_session.folder), ReconstructionSettings()
    early = start_reading(session, settings)
    assert early is not None
    shared = run_reconstruction(session, settings, early=early)
    assert early.pid is None  # reaped once the stations were read
    csv_two, report_two = _write(reconstruction, tmp_path / "two")
    csv_early, report_early = _write(shared, tmp_path / "early")
    assert csv_early == csv_two
    assert report_early == report_two
    for name in ("cloud.ply", "leaves.csv"):
        assert (tmp_path / "early" / name).read_bytes() == (tmp_path / "two" / name).read_bytes()
    assert shared.warnings == reconstruction.warnings
    assert repr(shared.organs) == repr(reconstruction.organs)
