"""Registration does each piece of work once (issue 22): counted, never timed."""

from __future__ import annotations

import numpy as np
import pytest

from devices.geometry import invert, make_transform, rotation_z, transform_points
from fieldapp.recon import guards, pairwise, register
from fieldapp.recon.pairwise import Overlap, register_overlap
from fieldapp.recon.settings import RegistrationSettings

from .synthetic import cylinder


def _overlap() -> tuple[Overlap, np.ndarray]:
    """Bumpy ground with two stems, b's copy moved by 3 cm / 1.5 degrees: (overlap, T_a_b)."""
    rng = np.random.default_rng(4)
    xy = rng.uniform(-0.8, 0.8, (15_000, 2))
    z = 0.015 * np.sin(4 * xy[:, 0]) * np.cos(3 * xy[:, 1]) + 0.004 * np.sin(11 * xy[:, 0])
    stems = [cylinder(rng, x, y, 0.01, 0.25, 800) for x, y in ((0.3, -0.2), (-0.4, 0.3))]
    scene = np.concatenate([np.column_stack([xy, z]), *stems])
    T_a_b = make_transform(rotation_z(1.5), np.array([0.03, -0.02, 0.0]))
    return Overlap(1, 2, scene, transform_points(invert(T_a_b), scene)), T_a_b


def test_the_fine_sizes_share_one_cloud_and_each_cloud_is_prepared_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The registration points are 1-2 cm apart, so a 2 cm grid keeps nearly the 8 mm grid's
    points: the 2 cm size runs (with its own 10 cm reach) on the 8 mm cloud."""
    prepared: list[float] = []
    real = pairwise.preprocess

    def counted(points_m, voxel_m, threads=1):  # type: ignore[no-untyped-def]
        prepared.append(voxel_m)
        return real(points_m, voxel_m, threads)

    reaches: list[float] = []
    real_gicp = pairwise.gicp

    def reached(target, source, tree, T, settings, voxel_m):  # type: ignore[no-untyped-def]
        reaches.append(voxel_m)
        return real_gicp(target, source, tree, T, settings, voxel_m)

    monkeypatch.setattr(pairwise, "preprocess", counted)
    monkeypatch.setattr(pairwise, "gicp", reached)
    overlap, T_a_b = _overlap()
    fit = register_overlap(overlap, np.zeros(3), RegistrationSettings())
    assert prepared == [0.1, 0.1, 0.05, 0.05, 0.008, 0.008]  # target and source per cloud
    assert reaches == [0.1, 0.05, 0.02, 0.008]  # every size of the ladder still runs
    assert np.abs(fit.T_a_b[:3, 3] - T_a_b[:3, 3]).max() < 0.002


def test_a_pair_is_scored_and_weighted_without_a_tree_of_its_own(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Fitness, RMSE and the information come from GICP's finest clouds, their tree and
    normals: no second k-d tree of the overlap, no normals estimated again."""

    def no_tree(*args: object, **kwargs: object) -> None:
        raise AssertionError("a k-d tree built again")

    monkeypatch.setattr(pairwise, "cKDTree", no_tree)
    overlap, _ = _overlap()
    fit = register_overlap(overlap, np.zeros(3), RegistrationSettings())
    assert fit.converged and fit.fitness > 0.95 and fit.rmse_m < 0.002
    values = np.linalg.eigvalsh(fit.information)
    assert values.min() > 0.0  # relief and stems hold all six components
    # flat ground would hold height and tilt far better than position: here the relief holds
    # the position too, a tenth of the height's or better
    assert fit.information[3, 3] > 0.01 * fit.information[5, 5]


def test_the_overlap_checks_take_a_sample_of_the_points(monkeypatch: pytest.MonkeyPatch) -> None:
    queried: list[int] = []
    real = guards.overlap_disagreement

    def counted(points_m, tree, T, cap):  # type: ignore[no-untyped-def]
        queried.append(len(points_m))
        return real(points_m, tree, T, cap)

    monkeypatch.setattr(guards, "overlap_disagreement", counted)
    overlap, _ = _overlap()
    points = {1: overlap.points_a_m, 2: overlap.points_b_m}
    coarse = {1: np.eye(4), 2: np.eye(4)}
    settings = RegistrationSettings(min_overlap_m2=1.0)  # a 1.6 m square
    steps = register.register_stations(points, coarse, np.zeros(3), 1, settings)
    while True:
        try:
            next(steps)
        except StopIteration as done:
            assert done.value[2].verdict == "refined"
            break
    crop = pairwise.find_overlaps(points, settings)[0].points_b_m  # station 2's side
    expected = len(crop[:: guards.SAMPLE_STRIDE])
    assert queried == [expected, expected] and expected < len(crop) / 3  # coarse, corrected


def test_a_pairs_source_is_its_shared_cells_and_its_target_has_a_margin() -> None:
    """b's points beyond a's view have nothing to match: only the target keeps the one-cell
    margin (for the arrival error)."""
    rng = np.random.default_rng(1)
    a = np.column_stack([rng.uniform(0.0, 2.0, (20_000, 2)), np.zeros(20_000)])
    b = a + np.array([1.0, 0.0, 0.0])  # overlapping in x 1.0-2.0
    settings = RegistrationSettings(min_overlap_m2=1.0)
    overlap = pairwise.find_overlaps({1: a, 2: b}, settings)[0]
    cell_m = settings.overlap_cell_m
    assert overlap.points_b_m[:, 0].min() >= 1.0 and overlap.points_b_m[:, 0].max() < 2.0
    assert overlap.points_a_m[:, 0].min() < 1.0 - 0.5 * cell_m  # the margin, a's side
    assert overlap.points_a_m[:, 0].min() >= 1.0 - cell_m


def _placed(steps: register.RegistrationSteps) -> dict[int, register.StationRegistration]:
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value


def test_a_run_with_a_wider_prior_from_the_same_poses_registers_no_pair_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``stages.join_stations`` registers again with the arrival uncertainty widened; a pair's
    fit does not depend on it, so a run from the same starting poses takes the fits of the
    run before, and places every station as registering each pair again would."""
    registered: list[tuple[int, int]] = []
    real = register._register_pair

    def counted(job: register.PairJob) -> pairwise.PairFit:
        registered.append((job[0].a, job[0].b))
        return real(job)

    monkeypatch.setattr(register, "_register_pair", counted)
    overlap, _ = _overlap()
    points = {1: overlap.points_a_m, 2: overlap.points_b_m}
    coarse = {1: np.eye(4), 2: np.eye(4)}
    settings = RegistrationSettings(min_overlap_m2=1.0)
    wider = settings.model_copy(update={"arrival_sigma_m": 0.12, "arrival_sigma_deg": 6.0})
    known = register.PairFits()

    _placed(register.register_stations(points, coarse, np.zeros(3), 1, settings, 1, known))
    first = len(registered)
    assert first >= 1 and len(known) == first
    again = _placed(register.register_stations(points, coarse, np.zeros(3), 1, wider, 1, known))
    assert len(registered) == first  # every fit taken from the run before

    alone = _placed(register.register_stations(points, coarse, np.zeros(3), 1, wider))
    assert len(registered) > first  # without them the pair is registered again ...
    assert again[2].verdict == alone[2].verdict == "refined"
    np.testing.assert_array_equal(again[2].T_correction, alone[2].T_correction)  # ... the same

    moved = {1: np.eye(4), 2: make_transform(rotation_z(0.5), np.array([0.01, 0.0, 0.0]))}
    counted_before = len(registered)
    _placed(register.register_stations(points, moved, np.zeros(3), 1, wider, 1, known))
    assert len(registered) > counted_before  # from other starting poses, a new fit
