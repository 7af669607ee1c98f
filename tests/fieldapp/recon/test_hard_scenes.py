"""Issue 19's targets on the simulator's scenes with few features: reference spheres on bare
soil, and bare soil alone (arrival errors 3 cm / 1.5 degrees).

Each session is two side-by-side stations (4 and 5, eight views each): one overlap to
register, and both cameras see every sphere, so a misplaced station draws each sphere twice.
About 14 s of CPU per sphere session and 10 s per soil session (rendering 16 frames and
reconstructing them): the targets are end-to-end figures, there is no cheaper way to check
them. One more bare-soil session of four stations (a 2 x 2 block, about 15-20 s) checks that
pairs fitting in more than one place never leave a station silently wrong.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from devices.geometry import invert, pose_error
from fieldapp.cli import main
from fieldapp.evaluate.sphere_outputs import all_distances
from fieldapp.evaluate.spheres import find_spheres, within_fraction
from fieldapp.io.session import load_session
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.result import Reconstruction
from fieldapp.recon.settings import ReconstructionSettings

pytestmark = pytest.mark.slow  # four simulated sessions, each reconstructed once


@dataclass(frozen=True)
class Run:
    result: Reconstruction
    truth: dict[str, Any]


def _run(folder: Path, scene: str, seed: int, stations: str = "4,5") -> Run:
    options = ["--scene", scene, "--seed", str(seed), "--stations", stations]
    assert main(["simulate", "--out", str(folder), *options, "--arrival-error", "0.03,1.5"]) == 0
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    return Run(result, json.loads((folder / "truth.json").read_text()))


@pytest.fixture(scope="module", params=[0, 1], ids=lambda seed: f"seed{seed}")
def spheres(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Run:
    return _run(tmp_path_factory.mktemp("spheres") / "session", "spheres", request.param)


@pytest.fixture(scope="module", params=[0, 1], ids=lambda seed: f"seed{seed}")
def soil(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Run:
    return _run(tmp_path_factory.mktemp("soil") / "session", "soil", request.param)


def _station_errors(run: Run) -> dict[int, tuple[float, float]]:
    """Each station's pose relative to the reference against the truth: (m, deg)."""
    T = {int(s): np.array(m) for s, m in run.truth["T_field_camera"].items()}
    reference = run.result.reference
    return {
        station: pose_error(
            run.result.T_reference_station(station), invert(T[reference]) @ T[station]
        )
        for station in run.result.registrations
    }


def _assert_stations_within_5_mm_and_0_2_degrees(run: Run) -> None:
    for station, (translation_m, rotation_deg) in _station_errors(run).items():
        registration = run.result.registrations[station]
        assert translation_m < 0.005 and rotation_deg < 0.2, (station, translation_m)
        assert registration.verdict in ("refined", "reference"), registration.message
    assert not [w for w in run.result.warnings if "ground not found" in w]


def test_sphere_points_lie_within_half_a_centimetre_of_their_spheres(spheres: Run) -> None:
    # no green contrast: soil and spheres are told apart by geometry, the soil sample stays
    # for levelling and registration (without it the stations were not levelled: 83.5 %)
    assert all("geometry" in s for s in spheres.result.separation.values())
    diameters = [s["diameter_mm"] for s in spheres.truth["spheres"]]
    fits = find_spheres(spheres.result.cloud.points, diameters)
    assert all(f.found for f in fits), [f.message for f in fits if not f.found]
    distances = all_distances(fits)
    assert within_fraction(distances, 0.5) >= 0.90  # measured: 99.9 % (paper: 55 %)
    assert within_fraction(distances, 1.2) >= 0.98  # measured: 100 % (paper: 91 %)


def test_stations_of_a_sphere_plot_are_within_5_mm_and_0_2_degrees(spheres: Run) -> None:
    _assert_stations_within_5_mm_and_0_2_degrees(spheres)


def test_stations_on_bare_soil_are_within_5_mm_and_0_2_degrees(soil: Run) -> None:
    _assert_stations_within_5_mm_and_0_2_degrees(soil)


def test_a_block_of_bare_soil_is_never_silently_wrong(tmp_path: Path) -> None:
    """Stations 4, 5, 7 and 8 of bare soil seed 1: three of the six pairs settled a clod
    wavelength off (127-198 mm) and agreed with each other; before the probes for a second
    minimum they outvoted the two right pairs and stations 7 and 8 ended 128-138 mm off, yet
    "refined". Since a pair's source is only its shared cells (issue 22) no pair slides here
    and the probes find no second minimum; every station must still be within 5 mm and 0.2
    degrees, or flagged unreliable (the probes themselves: test_ambiguity.py). About 12 s of
    CPU (rendering 32 frames and reconstructing them)."""
    run = _run(tmp_path / "session", "soil", 1, "4,5,7,8")
    verdicts = {s: r.verdict for s, r in run.result.registrations.items()}
    for station, (translation_m, rotation_deg) in _station_errors(run).items():
        assert verdicts[station] in ("refined", "reference", "unreliable"), verdicts
        if verdicts[station] != "unreliable":
            assert translation_m < 0.005 and rotation_deg < 0.2, (station, translation_m)
    assert "refined" in verdicts.values()  # measured: all three refined, within 2.2 mm
