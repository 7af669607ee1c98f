"""Small matrix products over many points without BLAS.

numpy hands ``(N, 3) @ (3, 3)`` to a threaded BLAS, which on a busy 2-core machine spends tens
of milliseconds synchronising its threads for a product that takes under one millisecond
column by column. The renderer does several per frame, so it uses these instead.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def rotate_t(R: NDArray[np.floating], vectors_t: NDArray[np.floating]) -> NDArray[np.float32]:
    """``(R @ vectors_t).T`` as (N, 3) float32, for (3, 3) ``R`` and (3, N) ``vectors_t``."""
    out = np.empty((vectors_t.shape[1], 3), np.float32)
    for k in range(3):
        out[:, k] = R[k, 0] * vectors_t[0] + R[k, 1] * vectors_t[1] + R[k, 2] * vectors_t[2]
    return out


def apply(T: NDArray[np.float64], points: NDArray[np.floating]) -> NDArray[np.float64]:
    """``T`` (4, 4) applied to ``points`` (N, 3): (N, 3) float64."""
    out = np.empty((len(points), 3), np.float64)
    for k in range(3):
        out[:, k] = (
            T[k, 0] * points[:, 0] + T[k, 1] * points[:, 1] + T[k, 2] * points[:, 2] + T[k, 3]
        )
    return out
