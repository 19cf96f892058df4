"""Intervals computed by hand."""
from __future__ import annotations

import math

import pytest

from dfrl.experiments.science.statistics import difference, interval, t975


def test_interval_by_hand() -> None:
    # values 1, 2, 3: mean 2, sd 1, se 1/sqrt(3), t(2) = 4.303
    iv = interval([1.0, 2.0, 3.0])
    assert iv.mean == 2.0 and iv.n == 3
    assert iv.half == pytest.approx(4.303 / math.sqrt(3))
    assert iv.excludes(10.0) and not iv.excludes(2.5)
    assert math.isnan(interval([5.0]).half) and not interval([5.0]).excludes(0.0)


def test_t_quantiles_and_errors() -> None:
    assert t975(1) == 12.706 and t975(30) == 2.042
    assert t975(60) == pytest.approx(2.000, abs=0.005)     # exact 2.000
    assert t975(120) == pytest.approx(1.980, abs=0.005)    # exact 1.980
    with pytest.raises(ValueError):
        interval([])
    with pytest.raises(ValueError, match="NaN"):
        interval([1.0, float("nan")])


def test_welch_difference() -> None:
    d = difference([10.0, 11.0, 12.0], [1.0, 2.0, 3.0])
    assert d.mean == pytest.approx(9.0)
    assert d.excludes(0.0)
    same = difference([1.0, 2.0, 3.0], [1.5, 2.5, 2.0])
    assert not same.excludes(0.0)
