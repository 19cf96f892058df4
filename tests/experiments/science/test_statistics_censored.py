"""Times to a target that some runs never reach: Kaplan-Meier, its median and the bootstrap of
a ratio of medians, against values worked out by hand in the comments."""

from __future__ import annotations

import math

import pytest

from dfrl.experiments.science.censored import (
    censored_ratio,
    kaplan_meier,
    km_median,
    km_median_interval,
)
from dfrl.experiments.science.statistics import Outcome, judge


def test_kaplan_meier_by_hand() -> None:
    # times 3 (reached), 5 (censored), 5 (reached), 8 (reached), 10 (censored), 12 (reached)
    # u = 3: 6 at risk, 1 event -> S = 5/6
    # u = 5: 5 at risk (the run censored at 5 still counts), 1 event -> 5/6 x 4/5 = 2/3
    # u = 8: 3 at risk (8, 10, 12), 1 event -> 2/3 x 2/3 = 4/9
    # u = 12: 1 at risk, 1 event -> 0
    steps = kaplan_meier([3, 5, 5, 8, 10, 12], [True, False, True, True, False, True])
    assert [u for u, _ in steps] == [3, 5, 8, 12]
    assert [s for _, s in steps] == pytest.approx([5 / 6, 2 / 3, 4 / 9, 0.0])
    assert km_median([3, 5, 5, 8, 10, 12], [1, 0, 1, 1, 0, 1]) == 8.0  # first S <= 1/2
    # no censoring: S = 3/4, 1/2 at 1, 2: the median is 2
    assert km_median([4, 2, 3, 1], [1, 1, 1, 1]) == 2.0


def test_censored_runs_are_not_counted_as_reaching_at_the_budget() -> None:
    # one run reached at 2, three never did within the budget 8: S(2) = 3/4 and nothing after,
    # so the median lies beyond the budget; counting the three as reaching at 8 (the control)
    # would give a median of 8
    assert km_median([2, 8, 8, 8], [True, False, False, False]) == math.inf
    assert km_median([2, 8, 8, 8], [True, True, True, True]) == 8.0
    assert kaplan_meier([8, 8], [False, False]) == []
    with pytest.raises(ValueError):
        kaplan_meier([1, 2], [True])
    with pytest.raises(ValueError):
        km_median([1, float("nan")], [True, True])


def test_ratio_of_uncensored_constant_groups_is_exact() -> None:
    # every resample of (6, 6, 6) has median 6 and of (2, 2, 2) median 2: the ratio is 3 in
    # every resample, so the interval is [3, 3]
    r = censored_ratio(([6, 6, 6], [1, 1, 1]), ([2, 2, 2], [1, 1, 1]), resamples=200)
    assert (r.estimate, r.low, r.high, r.known, r.n) == (3.0, 3.0, 3.0, "exact", 3)
    assert r.p_value(1.0) == 0.0 and r.p_value(3.0) == 1.0
    assert judge(r, 1.0, "above", 3).outcome is Outcome.HOLDS
    assert judge(r, 3.5, "above", 3).outcome is Outcome.REFUTED  # 3 <= 3.5: excluded
    assert judge(r, 1.0, "above", 4).outcome is Outcome.CANNOT_JUDGE  # n = 3 < 4


def test_a_censored_median_makes_the_ratio_a_bound() -> None:
    # T(1): all three censored at 12 -> its median is only known to exceed 12; T(N): 8 each.
    # The ratio is at least 12 / 8 = 1.5, with no upper end. Counting the censored runs as
    # reaching at 12 (the control) would give exactly 1.5 and refute "above 2.5"; honestly
    # it is not significant.
    r = censored_ratio(([12, 12, 12], [0, 0, 0]), ([8, 8, 8], [1, 1, 1]), resamples=200)
    assert (r.known, r.estimate, r.low, r.high) == ("at least", 1.5, 1.5, math.inf)
    assert judge(r, 1.0, "above", 3).outcome is Outcome.HOLDS  # at least 1.5 > 1
    assert judge(r, 2.5, "above", 3).outcome is Outcome.NOT_SIGNIFICANT
    control = censored_ratio(([12, 12, 12], [1, 1, 1]), ([8, 8, 8], [1, 1, 1]), resamples=200)
    assert judge(control, 2.5, "above", 3).outcome is Outcome.REFUTED
    assert "smallest detectable effect inf" in judge(r, 2.5, "above", 3).words()
    # the other way round: T(N) censored at 12, T(1) = 6: the ratio is at most 0.5
    down = censored_ratio(([6, 6, 6], [1, 1, 1]), ([12, 12, 12], [0, 0, 0]), resamples=200)
    assert (down.known, down.estimate, down.low, down.high) == ("at most", 0.5, 0.0, 0.5)
    assert judge(down, 1.0, "above", 3).outcome is Outcome.REFUTED
    both = censored_ratio(([12, 12, 12], [0, 0, 0]), ([12, 12, 12], [0, 0, 0]), resamples=200)
    assert both.known == "unknown" and math.isnan(both.estimate)
    assert (both.low, both.high) == (0.0, math.inf)
    assert judge(both, 1.0, "above", 3).outcome is Outcome.NOT_SIGNIFICANT


def test_ratio_bootstrap_is_seeded_and_its_percentiles_by_enumeration() -> None:
    # group a: (4, 8), both reached; a resample is (4,4), (4,8), (8,4) or (8,8) with median
    # 4, 4, 4, 8 (KM: S(4) = 1/2 for a mixed pair): median 4 with probability 3/4, 8 with 1/4.
    # group b: (2, 2): median 2. The ratio is 2 or 4; the 2.5% point is 2 and the 97.5% is 4.
    r = censored_ratio(([4, 8], [1, 1]), ([2, 2], [1, 1]), resamples=4000, seed=5)
    assert (r.estimate, r.low, r.high) == (2.0, 2.0, 4.0)
    share_of_4 = float((r.draws[:, 0] == 4.0).mean())
    assert share_of_4 == pytest.approx(0.25, abs=0.03)
    again = censored_ratio(([4, 8], [1, 1]), ([2, 2], [1, 1]), resamples=4000, seed=5)
    assert (again.draws == r.draws).all()
    other = censored_ratio(([4, 8], [1, 1]), ([2, 2], [1, 1]), resamples=4000, seed=6)
    assert not (other.draws == r.draws).all()


def test_median_interval_with_censoring() -> None:
    # (4, 6, 8) reached, two censored at 12: S = 4/5, 3/5, 2/5 at 4, 6, 8 -> median 8.
    # Resamples with three or more censored runs have a median beyond: their low end is 12
    # (the largest time), the high end inf; such resamples are far more than 2.5%
    # (P(>= 3 of 5 draws censored) = 0.317), so the interval's upper end is open; resamples
    # with three or more 4s (P = 0.058 > 2.5%) have median 4, the lower end.
    b = km_median_interval([4, 6, 8, 12, 12], [1, 1, 1, 0, 0], resamples=2000, seed=1)
    assert b.estimate == 8.0
    assert b.low == 4.0 and b.high == math.inf
