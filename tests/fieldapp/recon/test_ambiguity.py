"""Probing a pair of stations for a second minimum (``fieldapp/recon/ambiguity.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from devices.geometry import Matrix4, invert, make_transform, rotation_z, transform_points
from fieldapp.recon import ambiguity, posegraph
from fieldapp.recon.pairwise import Overlap, PairFit
from fieldapp.recon.register import StationRegistration, register_stations
from fieldapp.recon.settings import RegistrationSettings

WAVELENGTH_M = 0.12


def _ground(rng: np.random.Generator, relief: str, n: int = 12_000) -> np.ndarray:
    """(n, 3) a 1.6 m square of ground: ``corrugated``, ridges every ``WAVELENGTH_M`` along x
    with a gentle slope along y (so y is held); ``bumpy``, waves of several lengths and
    directions, one minimum only."""
    xy = rng.uniform(-0.8, 0.8, (n, 2))
    if relief == "corrugated":
        z = 0.01 * np.sin(2 * np.pi * xy[:, 0] / WAVELENGTH_M) + 0.02 * np.sin(2.0 * xy[:, 1])
    else:
        z = 0.015 * np.sin(4 * xy[:, 0]) * np.cos(3 * xy[:, 1]) + 0.006 * np.sin(
            11 * xy[:, 0] - 7 * xy[:, 1] + 0.5
        )
    return np.column_stack([xy, z + rng.normal(0.0, 0.0005, n)])


def _probe(relief: str) -> ambiguity.Ambiguity | None:
    """Two samplings of the same ground, the pair's fit at the truth (identity)."""
    overlap = Overlap(
        1,
        2,
        _ground(np.random.default_rng(0), relief),
        _ground(np.random.default_rng(1), relief),
    )
    fit = PairFit(1, 2, np.eye(4), np.eye(6), True, 1.0, 0.001, 12_000)
    return ambiguity.probe(0, overlap, fit, np.eye(4), RegistrationSettings())


def test_a_corrugated_ground_fits_a_wavelength_away() -> None:
    found = _probe("corrugated")
    assert found is not None and (found.a, found.b) == (1, 2)
    shifts_m = sorted(float(T[0, 3]) for T in found.alternatives)
    assert shifts_m == pytest.approx([-WAVELENGTH_M, WAVELENGTH_M], abs=0.01)
    assert found.nearest_m == pytest.approx(WAVELENGTH_M, abs=0.01)


def test_a_ground_of_one_minimum_is_not_ambiguous() -> None:
    assert _probe("bumpy") is None


def _solution(sigma_m: float) -> posegraph.Solution:
    """Stations 1 (the reference) and 2 (1.6 m away) placed where they started, station 2 with
    an isotropic standard deviation of ``sigma_m`` and 0.1 degrees."""
    nodes = {1: np.eye(4), 2: make_transform(np.eye(3), np.array([1.6, 0.0, 0.0]))}
    covariance = np.diag([np.radians(0.1) ** 2] * 3 + [sigma_m**2] * 3)
    return posegraph.Solution(nodes, [], [], covariance={1: np.zeros((6, 6)), 2: covariance})


def _shift(x_m: float) -> Matrix4:
    return make_transform(np.eye(3), np.array([x_m, 0.0, 0.0]))


@pytest.mark.parametrize(
    ("sigma_m", "fit_x_m", "chosen"),
    [
        (0.005, 0.12, True),  # the plot places the pair to 2 cm (4 sigma): the fit at the
        # truth's neighbour minimum is far outside, the truth's inside
        (0.04, 0.12, False),  # 16 cm of reach: both minima lie within it, the plot cannot choose
    ],
)
def test_the_plot_chooses_a_minimum_only_when_it_places_the_pair_well(
    sigma_m: float, fit_x_m: float, chosen: bool
) -> None:
    solution = _solution(sigma_m)
    found = ambiguity.Ambiguity(0, 1, 2, (np.eye(4),), 0.12, 0.0, 0.12, _shift(fit_x_m))
    settled = ambiguity.settled({0: found}, solution, solution.T_field_node, RegistrationSettings())
    assert (0 in settled) is chosen
    if chosen:  # registered again from where the plot places b relative to a
        np.testing.assert_allclose(settled[0], np.eye(4), atol=1e-12)


def test_only_pairs_that_hold_their_horizontal_position_weakly_are_probed() -> None:
    soil = np.diag([1.0, 1.0, 1.0, 0.04**2, 0.05**2, 1.0])  # bare soil: 0.04-0.05
    plants = np.diag([1.0, 1.0, 1.0, 0.2**2, 0.3**2, 1.0])  # plants or spheres: 0.2-0.3
    assert ambiguity.weakly_constrained(1e4 * soil)
    assert not ambiguity.weakly_constrained(1e4 * plants)


def test_a_station_held_only_by_an_ambiguous_pair_is_flagged_with_the_reason() -> None:
    """Two stations 1.6 m apart on ground with 2 mm ridges every 12 cm along x (a gentle wave
    along y): the one pair holds x only by the ridges and fits as well a ridge either way.
    Nothing else places station 2, so the plot cannot choose: it is flagged, not refined."""

    def ground(seed: int, centre_x_m: float) -> np.ndarray:
        rng = np.random.default_rng(seed)
        xy = rng.uniform(-1.5, 1.5, (60_000, 2)) + np.array([centre_x_m, 0.0])
        z = 0.002 * np.sin(2 * np.pi * xy[:, 0] / WAVELENGTH_M) + 0.03 * np.sin(1.3 * xy[:, 1])
        return np.column_stack([xy, z + rng.normal(0.0, 0.0005, len(xy))])

    T_true = {1: np.eye(4), 2: _shift(1.6)}
    points = {s: transform_points(invert(T), ground(s, T[0, 3])) for s, T in T_true.items()}
    coarse = {1: T_true[1], 2: make_transform(rotation_z(0.5), np.array([1.63, -0.02, 0.0]))}
    steps = register_stations(points, coarse, np.zeros(3), 1, RegistrationSettings())
    while True:
        try:
            next(steps)
        except StopIteration as done:
            registrations: dict[int, StationRegistration] = done.value
            break
    assert registrations[2].verdict == "unreliable"
    assert "pair 1-2 fits as well" in registrations[2].message  # a ridge (12 cm) away
