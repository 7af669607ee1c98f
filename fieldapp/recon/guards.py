"""What the registration may believe: the expected error of the coarse poses and the checks a
correction must pass.

The base stops with an arrival error of ``arrival_sigma_m`` per horizontal axis and
``arrival_sigma_deg`` in yaw (levelling leaves ``level_sigma_deg`` of tilt and
``level_sigma_m`` of height). A station's coarse pose relative to the reference carries its
own arrival error and the reference's, whose yaw swings the station about the reference: the
farther the station, the larger its expected error (:func:`prior_covariance`). A correction is
acceptable when it lies within ``guard_sigmas`` (Mahalanobis) of that expectation, and kept
only when it makes the station's overlaps agree better than its coarse pose does
(:func:`overlap_disagreement`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, invert, transform_points
from fieldapp.recon import se3
from fieldapp.recon.settings import RegistrationSettings

REFINED = "refined"
COARSE_KEPT = "coarse kept"
UNRELIABLE = "unreliable"
REFERENCE = "reference"

SAMPLE_STRIDE = 4
"""The overlap checks take every this many of a station's overlap points (in the order they
came, 1 cm apart): a mean over 3-6 thousand capped distances instead of 12-25 thousand."""


def arrival_covariance(settings: RegistrationSettings) -> NDArray[np.float64]:
    """(6, 6) covariance of one station's pose error in its own frame (field axes)."""
    tilt = np.radians(settings.level_sigma_deg)
    yaw = np.radians(settings.arrival_sigma_deg)
    sigma = [tilt, tilt, yaw, settings.arrival_sigma_m, settings.arrival_sigma_m]
    return np.diag(np.square([*sigma, settings.level_sigma_m]))


def prior_covariance(
    T_field_node: Matrix4, T_field_reference: Matrix4, settings: RegistrationSettings
) -> NDArray[np.float64]:
    """(6, 6) covariance of a station's coarse pose relative to the reference, in the
    station's frame: its own arrival error plus the reference's carried over to it."""
    single = arrival_covariance(settings)
    A = se3.adjoint(invert(T_field_node) @ T_field_reference)
    covariance: NDArray[np.float64] = single + A @ single @ A.T
    return covariance


def sigma_m_deg(covariance: NDArray[np.float64]) -> tuple[float, float]:
    """(translation m, rotation deg): the largest standard deviation of each part."""
    return _largest_sigma(covariance[3:, 3:]), float(np.degrees(_largest_sigma(covariance[:3, :3])))


def _largest_sigma(covariance: NDArray[np.float64]) -> float:
    """The largest standard deviation of a (K, K) ``covariance`` (its largest eigenvalue's
    square root)."""
    return float(np.sqrt(max(np.linalg.eigvalsh(covariance).max(), 0.0)))


PARTS = (
    ("tilt", slice(0, 2), "deg", "registration.level_sigma_deg"),
    ("turn about the vertical", slice(2, 3), "deg", "registration.arrival_sigma_deg"),
    ("horizontal shift", slice(3, 5), "mm", "registration.arrival_sigma_m"),
    ("height", slice(5, 6), "mm", "registration.level_sigma_m"),
)
"""A correction's parts (rows of the twist, field axes: rotation x y z, translation x y z),
their units in messages and the setting that says how far each is expected to go."""


def most_out(correction: se3.Vector6, covariance: NDArray[np.float64], sigmas: float) -> str:
    """Which part of the (6,) ``correction`` lies farthest out of what ``covariance`` expects
    of it (:data:`PARTS`, each part's own Mahalanobis distance), its size, the size ``sigmas``
    standard deviations of that part would be, and the setting to widen if the base errs so:
    a correction turned down for its tilt said only "limit 177 mm / 8.49 deg", the horizontal
    and yaw limits, which its 119 mm and 4.98 deg were under."""

    def distance(part: slice) -> float:
        return mahalanobis(correction[part], covariance[part, part])

    name, part, unit, setting = max(PARTS, key=lambda p: distance(p[1]))
    size, spread = float(np.linalg.norm(correction[part])), _largest_sigma(covariance[part, part])
    if unit == "deg":
        size, spread = np.degrees(size), np.degrees(spread)
        shown = f"{size:.2f} deg where {sigmas:g} sigma is {sigmas * spread:.2f} deg"
    else:
        shown = f"{1000 * size:.0f} mm where {sigmas:g} sigma is {1000 * sigmas * spread:.0f} mm"
    return f"most of all its {name}: {shown} ({setting})"


def mahalanobis(correction: se3.Vector6, covariance: NDArray[np.float64]) -> float:
    """How many standard deviations of ``covariance`` the (6,) ``correction`` is."""
    return float(np.sqrt(correction @ np.linalg.solve(covariance, correction)))


def overlap_disagreement(
    station_points_m: NDArray[np.float64],
    neighbour: cKDTree,
    T_neighbour_station: Matrix4,
    max_distance_m: float,
) -> float:
    """Mean squared distance (m^2, each capped at ``max_distance_m``) of the station's overlap
    points (N, 3), moved by ``T_neighbour_station``, to the neighbour's, given as a k-d tree
    of them where they stand: distances do not change when both move, so one tree of each
    side serves every pose the guards try."""
    if len(station_points_m) == 0 or neighbour.n == 0:
        return max_distance_m**2
    distances, _ = neighbour.query(
        transform_points(T_neighbour_station, station_points_m),
        k=1,
        distance_upper_bound=max_distance_m,
    )
    return float(np.mean(np.minimum(distances, max_distance_m) ** 2))
