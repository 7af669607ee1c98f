"""Agreement figures against hand-worked values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fieldapp.evaluate.metrics import agreement, squared_pearson


def test_hand_worked_three_pairs():
    # a = 10, 12, 15; m = 11, 12, 13; d = -1, 0, 2
    result = agreement([10.0, 12.0, 15.0], [11.0, 12.0, 13.0])
    assert result.n == 3
    assert result.bias == pytest.approx(1 / 3)
    assert result.rmse == pytest.approx(math.sqrt(5 / 3))
    assert result.mape_percent == pytest.approx(100 / 3 * (1 / 11 + 2 / 13))
    # s_d^2 = ((4/3)^2 + (1/3)^2 + (5/3)^2) / 2 = 7/3
    assert result.loa_low == pytest.approx(1 / 3 - 1.96 * math.sqrt(7 / 3))
    assert result.loa_high == pytest.approx(1 / 3 + 1.96 * math.sqrt(7 / 3))
    # Sxy = 5, Sxx = 114/9, Syy = 2: r^2 = 25 / (228/9) = 75/76
    assert result.r2 == pytest.approx(75 / 76)


def test_perfect_fit():
    values = [3.0, 7.5, 12.0, 20.0]
    result = agreement(values, values)
    assert (result.r2, result.rmse, result.mape_percent, result.bias) == (1.0, 0.0, 0.0, 0.0)
    assert (result.loa_low, result.loa_high) == (0.0, 0.0)


def test_constant_bias():
    reference = np.array([10.0, 20.0, 40.0, 50.0])
    result = agreement(reference + 2.0, reference)
    assert result.r2 == pytest.approx(1.0)
    assert result.rmse == pytest.approx(2.0)
    assert result.bias == pytest.approx(2.0)
    assert result.mape_percent == pytest.approx(100 / 4 * (2 / 10 + 2 / 20 + 2 / 40 + 2 / 50))
    assert result.loa_low == pytest.approx(2.0)
    assert result.loa_high == pytest.approx(2.0)


def test_one_pair():
    result = agreement([12.0], [10.0])
    assert result.n == 1
    assert result.r2 is None  # undefined below three pairs
    assert result.rmse == pytest.approx(2.0)
    assert result.mape_percent == pytest.approx(20.0)
    assert result.bias == pytest.approx(2.0)
    assert result.loa_low is None and result.loa_high is None


def test_two_pairs():
    result = agreement([12.0, 18.0], [10.0, 20.0])  # d = 2, -2
    assert result.r2 is None  # two points always lie on a line
    assert result.rmse == pytest.approx(2.0)
    assert result.bias == pytest.approx(0.0)
    assert result.mape_percent == pytest.approx(15.0)
    assert result.loa_high == pytest.approx(1.96 * math.sqrt(8.0))
    assert result.loa_low == pytest.approx(-1.96 * math.sqrt(8.0))


def test_zero_variance_and_zero_reference_and_nothing():
    flat = agreement([5.0, 6.0, 7.0], [4.0, 4.0, 4.0])
    assert flat.r2 is None
    assert flat.rmse == pytest.approx(math.sqrt((1 + 4 + 9) / 3))
    assert agreement([1.0, 2.0, 3.0], [0.0, 2.0, 3.0]).mape_percent is None
    empty = agreement([], [])
    assert empty.n == 0 and empty.rmse is None and empty.r2 is None


def test_bad_input():
    with pytest.raises(ValueError, match="2 algorithm values but 1"):
        agreement([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="finite"):
        agreement([1.0, float("nan")], [1.0, 2.0])


@given(st.lists(st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)), min_size=3, max_size=30))
def test_r2_is_numpy_corrcoef_squared(pairs):
    a, m = np.array(pairs).T
    r2 = squared_pearson(a, m)
    if np.ptp(a) < 1e-6 or np.ptp(m) < 1e-6:
        return
    assert r2 == pytest.approx(np.corrcoef(a, m)[0, 1] ** 2, abs=1e-9)


def test_r2_of_tiny_values_does_not_underflow():
    # found by hypothesis: the product of two variances of ~1e-187 underflowed to 0
    tiny = 7.094698625978579e-94
    assert squared_pearson([0.0, 0.0, tiny], [0.0, tiny, 0.0]) == pytest.approx(0.25)
    assert squared_pearson([1e300, -1e300, 0.0], [1.0, 2.0, 3.0]) == pytest.approx(0.25)
