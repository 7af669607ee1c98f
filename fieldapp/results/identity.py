"""Plant identity across dates: one-to-one assignment by position in the field frame.

A plant's base does not move, so a plant seen on a later date is the known plant whose base is
nearest, provided it is within ``max_distance_m``; the assignment (Hungarian method, scipy's
``linear_sum_assignment``) is one-to-one and minimises the total distance, so two neighbours
never collapse into one plant. Whatever is left unassigned is a new plant.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def match_positions(
    known_xy_m: NDArray[np.float64], observed_xy_m: NDArray[np.float64], max_distance_m: float
) -> list[int | None]:
    """For each observed position, the index of the known position it is, or ``None``.

    ``known_xy_m``: (K, 2), ``observed_xy_m``: (N, 2), field frame, metres.
    """
    if max_distance_m <= 0.0:
        raise ValueError("max_distance_m must be positive")
    known = np.asarray(known_xy_m, np.float64).reshape(-1, 2)
    observed = np.asarray(observed_xy_m, np.float64).reshape(-1, 2)
    matches: list[int | None] = [None] * len(observed)
    if len(known) == 0 or len(observed) == 0:
        return matches
    from scipy.optimize import linear_sum_assignment  # here: SciPy costs the GUI's start-up

    distance = np.linalg.norm(observed[:, None, :] - known[None, :, :], axis=2)
    # Pairs beyond the bound cost more than any set of admissible pairs: the assignment first
    # maximises the number of admissible pairs, then minimises their total distance.
    forbidden = 1.0 + max_distance_m * (min(len(known), len(observed)) + 1)
    cost = np.where(distance <= max_distance_m, distance, forbidden)
    rows, cols = linear_sum_assignment(cost)
    for row, col in zip(rows, cols, strict=True):
        if distance[row, col] <= max_distance_m:
            matches[int(row)] = int(col)
    return matches
