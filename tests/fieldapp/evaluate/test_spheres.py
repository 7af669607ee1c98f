"""Reference spheres found in a Kinect-like cloud; distances binned as the paper does."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fieldapp.cli import main
from fieldapp.evaluate.sphere_outputs import all_distances, spheres_csv
from fieldapp.evaluate.spheres import bin_fractions, find_spheres, fit_sphere, within_fraction
from fieldapp.recon.exg import BY_COLOUR, Separation

from .synthetic_spheres import sphere_cloud, sphere_truth

DIAMETERS = [200.0, 300.0, 350.0, 400.0, 500.0, 600.0]


@pytest.fixture(scope="module")
def fits():
    return find_spheres(sphere_cloud(seed=4), DIAMETERS)


def test_all_six_found_where_they_are(fits):
    truth = dict(sphere_truth())
    for fit in fits:
        assert fit.found, fit.message
        assert np.linalg.norm(fit.center_m - truth[fit.diameter_mm]) < 0.003
        assert fit.free_radius_m == pytest.approx(fit.diameter_mm / 2000, rel=0.02)
        assert len(fit.distances_m) > 1000


def test_beats_the_paper(fits):
    everything = all_distances(fits)
    assert within_fraction(everything, 0.5) > 0.5526
    assert within_fraction(everything, 0.8) > 0.7688
    fractions = bin_fractions(everything)
    assert fractions.sum() == pytest.approx(1.0)
    # 2 % flying pixels spread over +-5 cm: some must land beyond 1.2 cm
    assert 0.003 < fractions[-1] < 0.03


def test_a_missing_sphere_is_not_invented():
    fits = find_spheres(sphere_cloud(seed=5, missing_mm=350.0), DIAMETERS)
    assert [f.found for f in fits] == [True, True, False, True, True, True]
    assert fits[2].message


def test_bins_and_csv_by_hand():
    distances = np.array([0.001, -0.003, 0.006, 0.01, -0.02, 0.0019])
    assert list(bin_fractions(distances)) == pytest.approx([2 / 6, 1 / 6, 1 / 6, 1 / 6, 1 / 6])
    assert within_fraction(distances, 0.5) == pytest.approx(3 / 6)
    assert within_fraction(np.zeros(0), 0.5) == 0.0


def test_algebraic_fit_is_exact_on_exact_points():
    rng = np.random.default_rng(0)
    normals = rng.normal(size=(50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    center, radius = fit_sphere(np.array([0.3, -0.2, 0.1]) + 0.25 * normals)
    assert center == pytest.approx([0.3, -0.2, 0.1], abs=1e-9)
    assert radius == pytest.approx(0.25, abs=1e-9)


def test_csv_lists_every_sphere_and_the_total(fits):
    lines = spheres_csv(fits).splitlines()
    assert len(lines) == 1 + 6 + 1
    assert lines[-1].startswith("all,6,")


def _results(folder, separation):
    """A results folder holding the synthetic spheres' cloud and, unless ``separation`` is
    None, a report.json with that ``plant_separation``."""
    from fieldapp.io.ply import write_ply

    folder.mkdir()
    points = sphere_cloud(seed=4)
    vertices = np.empty(len(points), [("x", "f4"), ("y", "f4"), ("z", "f4")])
    vertices["x"], vertices["y"], vertices["z"] = points.T
    write_ply(folder / "cloud.ply", vertices)
    if separation is not None:
        (folder / "report.json").write_text(json.dumps({"plant_separation": separation}))
    return folder


def test_spheres_of_a_reconstruction_that_kept_only_green_points_are_warned_of(tmp_path, capsys):
    """Reconstructed with the defaults, a plot of spheres among plants keeps only green points:
    the spheres are gone from cloud.ply and the search may fit one to the leaves. The CLI says
    so, naming the report and the stations, and how to reconstruct for the spheres."""
    by_colour, by_geometry = BY_COLOUR.describe(), Separation("geometry", "no colour").describe()
    folder = _results(tmp_path / "green", {"1": by_colour, "2": by_geometry, "10": by_colour})
    assert main(["evaluate", "spheres", str(folder)]) == 0  # these spheres are all there
    err = capsys.readouterr().err
    assert f"{folder / 'report.json'}: stations 1, 10 kept only green points" in err
    assert "FIELDAPP_RECONSTRUCTION__FILTERS__EXG_THRESHOLD=-1" in err


@pytest.mark.parametrize("separation", [None, {"1": "plants separated by geometry: no colour"}])
def test_spheres_of_a_reconstruction_that_kept_every_point_are_not_warned_of(
    tmp_path, capsys, separation
):
    folder = _results(tmp_path / "all", separation)
    assert main(["evaluate", "spheres", str(folder)]) == 0
    assert "warning" not in capsys.readouterr().err
