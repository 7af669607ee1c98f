import numpy as np
import pytest

from devices.geometry import invert, make_transform, pose_error, rotation_z, transform_points
from fieldapp.recon.register import (
    IcpOutcome,
    icp,
    overlap_mask,
    plausibility_problem,
    register_stations,
    registration_order,
    score,
)
from fieldapp.recon.settings import RegistrationSettings

from .synthetic import cylinder


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


def test_overlap_sphere_is_between_the_stations() -> None:
    a, b = np.array([0.0, 0.0, 0.0]), np.array([1.6, 0.0, 0.0])
    points = np.array([[0.8, 0.0, 0.0], [0.8, 0.79, 0.0], [0.8, 0.0, 0.81], [0.0, 0.0, 0.0]])
    assert overlap_mask(points, a, b).tolist() == [True, True, False, True]


def test_registration_order_goes_outward_from_the_reference() -> None:
    centres = {s: np.array([(s - 1) % 3 * 1.6, (s - 1) // 3 * 1.6, 0.0]) for s in range(1, 10)}
    order = registration_order(centres, 5)
    stations = [s for s, _ in order]
    assert stations[:4] == [2, 4, 6, 8]
    assert sorted(stations) == [1, 2, 3, 4, 6, 7, 8, 9]
    for station, neighbours in order:
        placed = [5, *stations[: stations.index(station)]]
        assert neighbours and set(neighbours) <= set(placed)
    assert dict(order)[1] == [2, 4]


def test_implausible_corrections_are_rejected() -> None:
    settings = RegistrationSettings(max_translation_m=0.1, max_rotation_deg=3.0, min_fitness=0.5)
    centre = np.array([1.0, 0.0, 0.0])

    def outcome(T: np.ndarray, converged: bool = True, fitness: float = 0.9) -> IcpOutcome:
        return IcpOutcome(T, converged, fitness, 0.001, 1000, 1000)

    assert plausibility_problem(outcome(np.eye(4)), centre, settings) is None
    far = make_transform(np.eye(3), np.array([0.2, 0.0, 0.0]))
    assert "moved" in str(plausibility_problem(outcome(far), centre, settings))
    turned = make_transform(rotation_z(5.0), np.zeros(3))
    assert "turned" in str(plausibility_problem(outcome(turned), np.zeros(3), settings))
    assert "converge" in str(
        plausibility_problem(outcome(np.eye(4), converged=False), centre, settings)
    )
    assert "fitness" in str(plausibility_problem(outcome(np.eye(4), fitness=0.1), centre, settings))


def test_score_counts_pairs_within_the_distance() -> None:
    target = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    source = np.array([[0.0, 0, 0.003], [5.0, 0, 0]])
    fitness, rmse = score(target, source, 0.01)
    assert fitness == pytest.approx(0.5) and rmse == pytest.approx(0.003)


def _two_stations(rng: np.random.Generator, T_error: np.ndarray) -> tuple[dict, dict, dict]:
    world = _scene(rng) + np.array([0.8, 0.0, 0.0])
    world = np.concatenate([world, _scene(rng) - np.array([0.8, 0.0, 0.0])])
    T_field_station_true = {
        1: np.eye(4),
        2: make_transform(rotation_z(90.0), np.array([1.6, 0, 0])),
    }
    points = {s: transform_points(invert(T), world) for s, T in T_field_station_true.items()}
    coarse = {1: np.eye(4), 2: T_error @ T_field_station_true[2]}
    return points, coarse, T_field_station_true


def test_stations_register_against_the_placed_ones_and_bad_ones_keep_coarse() -> None:
    rng = np.random.default_rng(3)
    T_error = make_transform(rotation_z(1.2), np.array([0.03, 0.02, -0.005]))
    points, coarse, truth = _two_stations(rng, T_error)
    placed = list(register_stations(points, coarse, np.zeros(3), 1, RegistrationSettings()))
    assert [p.station for p in placed] == [1, 2]
    assert placed[1].accepted and placed[1].neighbours == [1]
    translation_m, rotation_deg = pose_error(placed[1].T_field_station, truth[2])
    assert translation_m < 0.002 and rotation_deg < 0.05

    strict = RegistrationSettings(max_translation_m=0.001)
    kept = list(register_stations(points, coarse, np.zeros(3), 1, strict))[1]
    assert not kept.accepted and "coarse transform kept" in kept.message
    np.testing.assert_allclose(kept.T_field_station, coarse[2])
    off = list(
        register_stations(points, coarse, np.zeros(3), 1, RegistrationSettings(enabled=False))
    )[1]
    assert not off.accepted and off.message.startswith("ICP off")
