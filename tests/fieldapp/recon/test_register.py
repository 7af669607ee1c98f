"""Pairwise ICP and the plot's pose graph on synthetic stations with known poses."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from devices.geometry import invert, make_transform, pose_error, rotation_z, transform_points
from fieldapp.recon import guards, register
from fieldapp.recon.pairwise import find_overlaps, icp, preprocess, score
from fieldapp.recon.register import StationRegistration, register_stations
from fieldapp.recon.settings import RegistrationSettings

from .synthetic import cylinder

SPACING_M = 1.6
VIEW_RADIUS_M = 2.2


def _scene(rng: np.random.Generator) -> np.ndarray:
    """Bumpy ground (so it constrains all six degrees of freedom) with cylinders on it."""
    xy = rng.uniform(-1.0, 1.0, (40_000, 2))
    z = 0.02 * np.sin(4 * xy[:, 0]) * np.cos(3 * xy[:, 1])
    ground = np.column_stack([xy, z])
    plants = [
        cylinder(rng, x, y, 0.03, 0.3, 3000) for x, y in [(-0.4, 0.3), (0.3, -0.2), (0.5, 0.5)]
    ]
    return np.concatenate([ground, *plants])


def test_icp_recovers_a_few_cm_and_degrees() -> None:
    rng = np.random.default_rng(0)
    target = _scene(rng)
    T_true = make_transform(rotation_z(1.5), np.array([0.04, -0.03, 0.01]))
    source = transform_points(invert(T_true), _scene(np.random.default_rng(0)))
    outcome = icp(target, source, RegistrationSettings())
    translation_m, rotation_deg = pose_error(outcome.T_target_source, T_true)
    assert translation_m < 0.002 and rotation_deg < 0.05
    assert outcome.converged and outcome.fitness > 0.95 and outcome.rmse_m < 0.002


def test_score_counts_pairs_within_the_distance() -> None:
    target = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    source = np.array([[0.0, 0, 0.003], [5.0, 0, 0]])
    fitness, rmse = score(target, source, 0.01)
    assert fitness == pytest.approx(0.5) and rmse == pytest.approx(0.003)


def _world(rng: np.random.Generator, grid: int) -> np.ndarray:
    """Soil with gentle relief over the plot and a few stems: (N, 3), about 4 cm sampling."""
    half = (grid - 1) * SPACING_M / 2 + VIEW_RADIUS_M
    n = int((2 * half) ** 2 * 700)
    xy = rng.uniform(-half, half, (n, 2))
    z = 0.015 * np.sin(2.1 * xy[:, 0] + 0.4) * np.cos(1.7 * xy[:, 1]) + 0.004 * np.sin(
        9 * xy[:, 0] - 7 * xy[:, 1]
    )
    stems = [
        cylinder(rng, x, y, 0.01, 0.25, 600)
        for x, y in rng.uniform(-half + 0.3, half - 0.3, (grid * grid, 2))
    ]
    return np.concatenate([np.column_stack([xy, z]), *stems])


def _plot(
    seed: int, grid: int, sigma_m: float, sigma_deg: float
) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], dict[int, np.ndarray], int]:
    """Stations on a ``grid`` x ``grid`` plan, each seeing the world within 2.2 m: (points in
    the station frame, coarse poses (nominal), true poses, reference)."""
    rng = np.random.default_rng(seed)
    world = _world(rng, grid)
    points, coarse, truth = {}, {}, {}
    offset = (grid - 1) * SPACING_M / 2
    for station in range(1, grid * grid + 1):
        row, col = divmod(station - 1, grid)
        nominal = np.array([col * SPACING_M - offset, row * SPACING_M - offset, 0.0])
        coarse[station] = make_transform(np.eye(3), nominal)
        error = make_transform(
            rotation_z(rng.normal(0.0, sigma_deg)), np.r_[rng.normal(0.0, sigma_m, 2), 0.0]
        )
        truth[station] = coarse[station] @ error
        seen = world[np.hypot(*(world[:, :2] - nominal[:2]).T) < VIEW_RADIUS_M]
        points[station] = transform_points(invert(truth[station]), seen)
    reference = (grid * grid + 1) // 2
    return points, coarse, truth, reference


def _run(
    points: dict, coarse: dict, reference: int, settings: RegistrationSettings, threads: int = 1
) -> dict[int, StationRegistration]:
    steps = register_stations(points, coarse, np.zeros(3), reference, settings, threads)
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]


def _errors(result: dict, truth: dict, reference: int) -> dict[int, tuple[float, float]]:
    T_ref = result[reference].T_field_station
    return {
        s: pose_error(invert(T_ref) @ r.T_field_station, invert(truth[reference]) @ truth[s])
        for s, r in result.items()
    }


@pytest.mark.parametrize("seed", [0, 1])
def test_every_station_of_a_3x3_plot_lands_within_2_mm_and_0_1_degrees(seed: int) -> None:
    points, coarse, truth, reference = _plot(seed, 3, 0.03, 1.5)
    result = _run(points, coarse, reference, RegistrationSettings())
    for station, (translation_m, rotation_deg) in _errors(result, truth, reference).items():
        assert translation_m < 0.002 and rotation_deg < 0.1, (station, translation_m)
        assert result[station].verdict in ("refined", "reference")
        assert result[station].uncertainty_m is not None
    assert result[1].neighbours == [2, 4, 5]  # side and diagonal neighbours, not 3 or 7


def test_results_do_not_depend_on_the_thread_count() -> None:
    points, coarse, _, reference = _plot(2, 3, 0.03, 1.5)
    one = _run(points, coarse, reference, RegistrationSettings(), threads=1)
    two = _run(points, coarse, reference, RegistrationSettings(), threads=2)
    for station in one:
        assert one[station].T_field_station.tobytes() == two[station].T_field_station.tobytes()
        assert one[station].uncertainty_m == two[station].uncertainty_m


def test_a_correction_beyond_the_expected_arrival_error_keeps_the_coarse_pose() -> None:
    points, coarse, _, reference = _plot(0, 3, 0.03, 1.5)
    believed = RegistrationSettings(arrival_sigma_m=0.002, arrival_sigma_deg=0.05)
    result = _run(points, coarse, reference, believed)
    for station, registration in result.items():
        if station == reference:
            continue
        assert registration.verdict != "refined" and not registration.accepted
        np.testing.assert_array_equal(registration.T_correction, np.eye(4))
        np.testing.assert_array_equal(registration.T_field_station, coarse[station])
        assert "coarse pose kept" in registration.message
    off = _run(points, coarse, reference, RegistrationSettings(enabled=False))
    assert all(r.verdict in ("coarse kept", "reference") for r in off.values())


def test_a_correction_turned_down_names_the_part_of_it_farthest_out() -> None:
    """A correction is judged on its six components together: 50 mm and 3 degrees may pass
    as a shift and a turn about the vertical, not as a tilt, which levelling leaves within a
    degree. The reason says which part it was, its size against that part's own limit, and
    the setting that sets it."""
    settings = RegistrationSettings()
    covariance = guards.prior_covariance(make_transform(np.eye(3), np.r_[1.6, 0, 0]), np.eye(4),
                                         settings)  # fmt: skip
    tilted = np.r_[np.radians(3.0), 0.0, 0.0, 0.05, 0.0, 0.0]
    said = guards.most_out(tilted, covariance, 4.0)
    assert said.startswith("most of all its tilt: 3.00 deg where 4 sigma is ")
    assert "registration.level_sigma_deg" in said
    # the station's own tilt and the reference's, carried over unturned: sqrt(2) x 1 degree
    assert f"{4 * np.sqrt(2) * settings.level_sigma_deg:.2f} deg" in said  # 5.66
    shifted = np.r_[0.0, 0.0, np.radians(1.0), 0.25, 0.0, 0.0]
    said = guards.most_out(shifted, covariance, 4.0)
    assert said.startswith("most of all its horizontal shift: 250 mm where 4 sigma is ")
    assert "registration.arrival_sigma_m" in said


def test_overlaps_are_the_side_and_diagonal_neighbours() -> None:
    points, coarse, _, _ = _plot(0, 3, 0.0, 0.0)
    field = {s: transform_points(coarse[s], p) for s, p in points.items()}
    pairs = [(o.a, o.b) for o in find_overlaps(field, RegistrationSettings())]
    assert len(pairs) == 12 + 8  # 12 side pairs, 8 diagonal ones
    assert (1, 3) not in pairs and (1, 5) in pairs and (2, 6) in pairs


def test_the_expected_error_grows_with_the_distance_to_the_reference() -> None:
    settings = RegistrationSettings()
    reference = np.eye(4)
    near = guards.prior_covariance(make_transform(np.eye(3), np.r_[1.6, 0, 0]), reference, settings)
    far = guards.prior_covariance(make_transform(np.eye(3), np.r_[6.4, 0, 0]), reference, settings)
    (near_m, near_deg), (far_m, far_deg) = guards.sigma_m_deg(near), guards.sigma_m_deg(far)
    assert near_deg == pytest.approx(far_deg)  # yaw: the two stations' own errors
    assert far_m > 2.5 * near_m  # the reference's yaw swings a far station farther
    yaw = np.radians(settings.arrival_sigma_deg)
    assert far_m == pytest.approx(np.sqrt(2 * settings.arrival_sigma_m**2 + (6.4 * yaw) ** 2))


def test_closing_the_registration_cancels_the_pairs_not_started(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from fieldapp.recon import register

    points, coarse, _, reference = _plot(0, 3, 0.0, 0.0)
    started = []
    real = register.register_overlap

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        started.append(args[0])
        return real(*args, **kwargs)

    monkeypatch.setattr(register, "register_overlap", counted)
    steps = register_stations(points, coarse, np.zeros(3), reference, RegistrationSettings())
    fraction, message = next(steps)
    assert fraction == pytest.approx(1 / 20) and message == "stations 1-2 registered"
    steps.close()
    assert len(started) <= 2  # the first pair, and at most the one running when closed


@pytest.mark.slow  # 72 pairs
def test_a_5x5_plot_is_refined_to_the_corners() -> None:
    points, coarse, truth, reference = _plot(5, 5, 0.03, 1.5)
    result = _run(points, coarse, reference, RegistrationSettings())
    errors = _errors(result, truth, reference)
    assert max(t for t, _ in errors.values()) < 0.002 and max(r for _, r in errors.values()) < 0.1
    assert {r.verdict for r in result.values()} == {"reference", "refined"}
    corner, neighbour = result[1], result[reference - 1]
    assert corner.limit_m is not None and neighbour.limit_m is not None
    assert corner.limit_m > 2 * neighbour.limit_m  # the guard widens with the distance
    assert corner.limit_m > 0.4  # the fixed 20 cm guard rejected real corrections out here


def test_pairs_that_slid_into_another_minimum_are_registered_again_from_the_plot(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """GICP from the coarse poses can settle 10-20 cm off on smooth relief (bare soil, seed 1:
    4 of 20 pairs). Two of corner station 7's three pairs are made to do so here: they are
    registered again from the graph's first solution, found right and kept."""
    from dataclasses import replace

    from fieldapp.recon import register

    points, coarse, truth, reference = _plot(1, 3, 0.03, 1.5)
    real = register.register_overlap
    slid = make_transform(np.eye(3), np.array([0.10, 0.0, 0.0]))
    again = []

    def sliding(overlap, centre, settings, init_T_a_b=None, threads=1):  # type: ignore[no-untyped-def]
        if init_T_a_b is not None:
            again.append((overlap.a, overlap.b))
            return real(overlap, centre, settings, init_T_a_b, threads)
        fit = real(overlap, centre, settings, threads=threads)
        if (overlap.a, overlap.b) in ((4, 7), (5, 7)):
            return replace(fit, T_a_b=slid @ fit.T_a_b)
        return fit

    monkeypatch.setattr(register, "register_overlap", sliding)
    result = _run(points, coarse, reference, RegistrationSettings())
    assert again == [(4, 7), (5, 7)]
    assert result[7].neighbours == [4, 5, 8]  # without the second pass: [8]
    translation_m, rotation_deg = _errors(result, truth, reference)[7]
    assert translation_m < 0.002 and rotation_deg < 0.1


def test_gicp_gives_the_same_fit_on_one_and_two_threads() -> None:
    """Only the k-d trees and covariances use the threads (each point's its own): small_gicp's
    multi-threaded voxel sampling keeps a varying number of points, and its multi-threaded
    optimisation sums in the threads' order."""
    rng = np.random.default_rng(3)
    target = _scene(rng)
    T_true = make_transform(rotation_z(1.0), np.array([0.03, 0.02, -0.01]))
    source = transform_points(invert(T_true), _scene(np.random.default_rng(3)))
    for voxel_m in RegistrationSettings().voxel_sizes_m:
        (one, _), (two, _) = preprocess(target, voxel_m, 1), preprocess(target, voxel_m, 2)
        assert np.array_equal(one.points(), two.points())
        assert np.array_equal(np.array(one.covs()), np.array(two.covs()))
    fits = [icp(target, source, RegistrationSettings(), threads) for threads in (1, 2, 2)]
    assert all(np.array_equal(f.T_target_source, fits[0].T_target_source) for f in fits)
    assert pose_error(fits[0].T_target_source, T_true)[0] < 0.002


def test_openmp_threads_sleep_when_idle() -> None:
    """Spinning OpenMP threads cost two threads 75 % more CPU than one: the wait policy is set
    before the reconstruction loads small_gicp (the policy is read once, when it loads)."""
    code = (
        "import os, sys; import fieldapp.recon.pipeline; "
        "print(os.environ.get('OMP_WAIT_POLICY'), 'small_gicp' in sys.modules)"
    )
    environment = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    shown = subprocess.run(
        [sys.executable, "-c", code], env=environment, capture_output=True, text=True, check=True
    )
    assert shown.stdout.split() == ["PASSIVE", "True"]


def test_the_guards_overlap_checks_made_a_pair_at_a_time_equal_those_made_here(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Issue 22: with a worker process, each solution's overlap checks are computed ahead, a
    pair at a time on both processes; every station's agreement is bit for bit the one
    computed here with the trees kept for every solution."""
    checked = []
    ahead = register._Plot.agreement_terms

    def compared(plot: register._Plot, map_pairs: Any) -> dict:
        terms = ahead(plot, map_pairs)
        here = dataclasses.replace(plot, terms={})
        for station in sorted(set(plot.nodes) - set(plot.fixed) - {plot.reference}):
            if plot._implausible(station) is None:
                plot.terms = terms
                assert plot.agreement(station) == here.agreement(station)
                checked.append(station)
        return terms

    monkeypatch.setattr(register._Plot, "agreement_terms", compared)
    points, coarse, _, reference = _plot(2, 3, 0.03, 1.5)
    _run(points, coarse, reference, RegistrationSettings(), threads=2)
    assert len(checked) == 8


def test_the_guards_verdicts_are_the_same_on_two_processes() -> None:
    """Stations failing their guards, fixed one at a time: every solution's checks are made
    ahead on two processes, with the same verdicts and messages as on one."""
    points, coarse, _, reference = _plot(0, 3, 0.03, 1.5)
    for believed in (
        RegistrationSettings(arrival_sigma_m=0.002, arrival_sigma_deg=0.05),
        RegistrationSettings(arrival_sigma_m=0.02, arrival_sigma_deg=0.5),
    ):
        one = _run(points, coarse, reference, believed, threads=1)
        two = _run(points, coarse, reference, believed, threads=2)
        assert [(r.verdict, r.message) for r in one.values()] == [
            (r.verdict, r.message) for r in two.values()
        ]
        for station in one:
            assert one[station].T_field_station.tobytes() == two[station].T_field_station.tobytes()
