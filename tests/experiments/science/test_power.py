"""The seeds an effect needs (``science/power.py``) on hand-computed numbers, checked against
the smallest detectable effect of a real interval."""

from __future__ import annotations

import math

import pytest

from dfrl.experiments.science.power import detectable_at, seeds_for, seeds_needed
from dfrl.experiments.science.statistics import interval


def test_detectable_at_by_hand() -> None:
    # sd 1, n 3: (t(0.975, 2) + t(0.8, 2)) / sqrt(3) = (4.30265 + 1.06066) / 1.73205
    assert detectable_at(1.0, 3) == pytest.approx(3.09651, abs=1e-4)
    # n 4: (3.18245 + 0.97847) / 2
    assert detectable_at(1.0, 4) == pytest.approx(2.08046, abs=1e-4)
    # the same D as the interval of three values of sd 1 reports
    assert detectable_at(1.0, 3) == pytest.approx(interval([1.0, 2.0, 3.0]).detectable())
    with pytest.raises(ValueError):
        detectable_at(1.0, 1)


def test_seeds_needed_is_the_first_n_that_reaches_the_effect() -> None:
    assert seeds_needed(1.0, 3.1) == 3  # D(3) = 3.0965 <= 3.1 < D(2) = 9.96
    assert seeds_needed(1.0, 3.09) == 4  # D(3) = 3.0965 > 3.09 >= D(4) = 2.080
    assert seeds_needed(1.0, -3.09) == 4  # a size: the sign does not matter
    n = seeds_needed(2.0, 0.5)
    assert detectable_at(2.0, n) <= 0.5 < detectable_at(2.0, n - 1)
    assert 120 <= n <= 130  # about (1.96 + 0.84)^2 x 16 = 125.6
    for bad in (0.0, math.inf):
        with pytest.raises(ValueError):
            seeds_needed(1.0, bad)


def test_seeds_for_a_measured_d_by_hand() -> None:
    # the speed-up study: D = 4.8 at n = 10; 10 x (ln 4.8 / ln 2.2)^2 = 39.58 -> 40
    assert seeds_for(10, 4.8, 2.2, "ratio") == 40
    assert seeds_for(10, 2.0, 1.0) == 40  # a difference: 10 x 2^2
    assert seeds_for(10, 1.0, 2.0) == 3  # already below: 10 / 4 = 2.5 -> 3
    with pytest.raises(ValueError, match="open"):
        seeds_for(10, math.inf, 1.0)
    with pytest.raises(ValueError):
        seeds_for(10, 4.8, 0.9, "ratio")
    with pytest.raises(ValueError):
        seeds_for(10, 4.8, 2.2, "log")
