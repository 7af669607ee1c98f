"""Agreement between the algorithm's and the reference measurements of a trait.

For pairs (a_i, m_i), i = 1..n, with differences d_i = a_i - m_i:

- ``r2``: the squared Pearson correlation of a and m, as the paper defines R2. ``None`` (not
  defined) when n < 3 (two points always lie on a line: r = +-1 says nothing) or when a or m
  has zero variance (the correlation is 0 / 0).
- ``rmse``: sqrt(sum d_i^2 / n), the standard root mean squared error (the paper's printed
  Eq. 10 misplaces the 1/n).
- ``mape_percent``: 100 / n * sum |d_i| / |m_i|; ``None`` when some m_i is 0.
- ``bias``: mean d_i (positive: the algorithm measures more).
- ``loa_low``, ``loa_high``: Bland-Altman 95 % limits of agreement, bias -+ 1.96 s_d with
  s_d the sample standard deviation (n - 1) of the d_i; ``None`` when n < 2.

Every figure is ``None`` when n = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

LOA_Z = 1.96
MIN_PAIRS_FOR_R2 = 3


@dataclass(frozen=True)
class Agreement:
    """Agreement figures in the unit of the trait (``mape_percent`` in %)."""

    n: int
    r2: float | None
    rmse: float | None
    mape_percent: float | None
    bias: float | None
    loa_low: float | None
    loa_high: float | None


def agreement(algorithm: ArrayLike, reference: ArrayLike) -> Agreement:
    """Agreement of ``algorithm`` (n,) with ``reference`` (n,), both finite."""
    a = np.asarray(algorithm, np.float64).ravel()
    m = np.asarray(reference, np.float64).ravel()
    if a.shape != m.shape:
        raise ValueError(f"{len(a)} algorithm values but {len(m)} reference values")
    if not (np.isfinite(a).all() and np.isfinite(m).all()):
        raise ValueError("values must be finite")
    n = len(a)
    if n == 0:
        return Agreement(0, None, None, None, None, None, None)
    d = a - m
    bias = float(d.mean())
    low = high = None
    if n >= 2:
        spread = LOA_Z * float(d.std(ddof=1))
        low, high = bias - spread, bias + spread
    mape = None if np.any(m == 0.0) else float(100.0 * np.mean(np.abs(d) / np.abs(m)))
    return Agreement(
        n=n,
        r2=squared_pearson(a, m),
        rmse=math.sqrt(float(np.mean(d * d))),
        mape_percent=mape,
        bias=bias,
        loa_low=low,
        loa_high=high,
    )


def squared_pearson(a: ArrayLike, m: ArrayLike) -> float | None:
    """r^2 of the Pearson correlation, or ``None`` when n < 3 or a variance is zero."""
    x = np.asarray(a, np.float64).ravel()
    y = np.asarray(m, np.float64).ravel()
    if len(x) < MIN_PAIRS_FOR_R2:
        return None
    dx, dy = x - x.mean(), y - y.mean()
    spread_x, spread_y = float(np.abs(dx).max()), float(np.abs(dy).max())
    if spread_x <= 1e-12 * float(np.abs(x).max()) or spread_y <= 1e-12 * float(np.abs(y).max()):
        return None  # a constant side, up to rounding (this also catches a zero spread)
    dx, dy = dx / spread_x, dy / spread_y  # r is scale-free; tiny values must not underflow
    r = float(dx @ dy) / math.sqrt(float(dx @ dx) * float(dy @ dy))
    return min(1.0, r * r)
