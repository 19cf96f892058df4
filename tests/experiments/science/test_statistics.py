"""The statistics module against values worked out by hand (in the comments) or read from
printed tables of Student's t, never from the implementation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dfrl.experiments.science.statistics import (
    Interval,
    Outcome,
    adjust,
    bootstrap,
    holm,
    interval,
    judge,
    paired,
    t975,
    t_cdf,
    t_quantile,
    welch,
)


def test_t_distribution_closed_forms() -> None:
    # df = 1 is Cauchy: F(t) = 1/2 + atan(t)/pi; F(1) = 1/2 + (pi/4)/pi = 0.75
    assert t_cdf(1.0, 1) == pytest.approx(0.75, abs=1e-12)
    # df = 2: F(t) = 1/2 + t / (2 sqrt(2 + t^2)); F(1) = 1/2 + 1/(2 sqrt 3) = 0.7886751
    assert t_cdf(1.0, 2) == pytest.approx(0.5 + 1 / (2 * math.sqrt(3)), abs=1e-12)
    # df = 3: F(t) = 1/2 + (t / (sqrt3 (1 + t^2/3)) + atan(t / sqrt3)) / pi; at t = 2:
    # 1.1547/2.3333 = 0.49487, atan(1.1547) = 0.85707, (0.49487 + 0.85707)/pi = 0.43034
    assert t_cdf(2.0, 3) == pytest.approx(0.93034, abs=1e-5)
    assert t_cdf(-2.0, 3) == pytest.approx(1 - 0.93034, abs=1e-5)
    # df = 2 inverts in closed form: t_p = (2p - 1) sqrt(2 / (4 p (1 - p)));
    # p = 0.975: 0.95 x sqrt(2 / 0.0975) = 4.30265; p = 0.8: 0.6 x sqrt(2 / 0.64) = 1.06066
    assert t_quantile(0.975, 2) == pytest.approx(4.30265, abs=1e-5)
    assert t_quantile(0.8, 2) == pytest.approx(1.06066, abs=1e-5)
    assert t_quantile(0.025, 2) == pytest.approx(-4.30265, abs=1e-5)


def test_t975_matches_printed_tables() -> None:
    # printed two-sided 95% values of Student's t (3 decimals)
    for df, printed in (
        (1, 12.706),
        (2, 4.303),
        (4, 2.776),
        (9, 2.262),
        (30, 2.042),
        (60, 2.000),
        (120, 1.980),
    ):
        assert t975(df) == pytest.approx(printed, abs=5e-4), df
    assert t975(1e7) == pytest.approx(1.95996, abs=1e-4)  # the normal quantile
    assert t975(2.5) < t975(2) and t975(2.5) > t975(3)  # Welch's df need not be whole
    with pytest.raises(ValueError):
        t975(0)


def test_interval_by_hand() -> None:
    # values 1, 2, 3: mean 2, sd 1, se 1/sqrt(3) = 0.57735, df 2, half 4.30265 x se = 2.48414
    iv = interval([1.0, 2.0, 3.0])
    assert (iv.mean, iv.n, iv.df) == (2.0, 3, 2.0)
    assert iv.se == pytest.approx(1 / math.sqrt(3))
    assert iv.half == pytest.approx(2.48414, abs=1e-5)
    assert iv.excludes(10.0) and not iv.excludes(2.5)
    # p against 0: t = 2 / 0.57735 = 2 sqrt 3 = 3.4641; df 2: P(|T| > t) = 1 - t / sqrt(2 + t^2)
    # = 1 - 3.4641 / 3.74166 = 0.074180
    assert iv.p_value(0.0) == pytest.approx(0.074180, abs=1e-6)
    assert iv.p_value(2.0) == pytest.approx(1.0)
    # smallest detectable effect, 80% power: (t975(2) + t0.8(2)) se = (4.30265 + 1.06066)
    # x 0.57735 = 3.09651
    assert iv.detectable() == pytest.approx(3.09651, abs=1e-4)
    one = interval([5.0])
    assert math.isnan(one.half) and not one.excludes(0.0) and math.isnan(one.p_value())
    with pytest.raises(ValueError):
        interval([])
    with pytest.raises(ValueError, match="NaN"):
        interval([1.0, float("nan")])


def test_paired_by_hand() -> None:
    # differences (5-4, 7-5, 9-9) = 1, 2, 0: mean 1, sd 1, half 4.30265 / sqrt 3 = 2.48414
    d = paired([5.0, 7.0, 9.0], [4.0, 5.0, 9.0])
    assert d.mean == pytest.approx(1.0) and d.half == pytest.approx(2.48414, abs=1e-5)
    assert d.n == 3 and d.df == 2
    with pytest.raises(ValueError, match="equal lengths"):
        paired([1.0, 2.0], [1.0])


def test_welch_by_hand() -> None:
    # a = 10, 11, 12 (mean 11, var 1), b = 1, 3, 5 (mean 3, var 4): difference 8;
    # va/na = 1/3, vb/nb = 4/3, se = sqrt(5/3)
    # = 1.29099; df = (5/3)^2 / ((1/3)^2/2 + (4/3)^2/2) = (25/9) / (17/18) = 50/17 = 2.9412
    d = welch([10.0, 11.0, 12.0], [1.0, 3.0, 5.0])
    assert d.mean == pytest.approx(8.0)
    assert d.se == pytest.approx(math.sqrt(5 / 3))
    assert d.df == pytest.approx(50 / 17)
    assert t975(2) > d.half / d.se > t975(3)  # between the df-2 and df-3 multipliers
    assert d.excludes(0.0)
    assert not welch([1.0, 2.0, 3.0], [1.5, 2.5, 2.0]).excludes(0.0)
    assert math.isnan(welch([1.0], [2.0, 3.0]).half)


def test_bootstrap_percentile_of_a_ratio_by_enumeration() -> None:
    # a = (1, 3) resampled: mean 1 (1/4), 2 (1/2), 3 (1/4); b = (1, 1) always 1. The ratio of
    # means is 1, 2 or 3 with these chances: the 2.5% quantile is 1, the 97.5% one is 3
    ratio = lambda a, b: a.mean() / b.mean()  # noqa: E731
    b = bootstrap([[1.0, 3.0], [1.0, 1.0]], ratio, resamples=4000, seed=7, method="percentile")
    assert (b.estimate, b.low, b.high) == (2.0, 1.0, 3.0)
    # constant samples: every resample gives the same ratio 2
    c = bootstrap([[2.0, 2.0, 2.0], [1.0, 1.0, 1.0]], ratio, resamples=200)
    assert (c.estimate, c.low, c.high) == (2.0, 2.0, 2.0)


def test_bootstrap_is_seeded_and_bca_shifts_with_skew() -> None:
    data = [[1.0, 3.0, 5.0, 9.0, 2.0, 14.0], [1.0, 1.0, 2.0, 4.0]]
    ratio = lambda a, b: a.mean() / b.mean()  # noqa: E731
    first = bootstrap(data, ratio, resamples=2000, seed=3)
    assert first == bootstrap(data, ratio, resamples=2000, seed=3)  # same seed, same interval
    assert first != bootstrap(data, ratio, resamples=2000, seed=4)
    assert first.low < first.estimate < first.high
    # the mean of a symmetric sample: BCa and percentile agree closely, both near the t interval
    sym = [list(np.linspace(-1.0, 1.0, 21))]
    mean = lambda a: a.mean()  # noqa: E731
    pc = bootstrap(sym, mean, resamples=4000, method="percentile")
    bca = bootstrap(sym, mean, resamples=4000, method="bca")
    assert bca.low == pytest.approx(pc.low, abs=0.03) and bca.high == pytest.approx(
        pc.high, abs=0.03
    )
    assert pc.high == pytest.approx(interval(sym[0]).high, abs=0.06)
    with pytest.raises(ValueError):
        bootstrap(data, ratio, method="basic")


def test_holm_by_hand() -> None:
    # p = .01, .04, .03, .005 (m = 4), sorted .005, .01, .03, .04 times 4, 3, 2, 1:
    # .02, .03, .06, .04 -> running maximum .02, .03, .06, .06; back in the order given:
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.5, 0.6]) == [1.0, 1.0]  # capped at 1
    out = holm([0.01, float("nan"), 0.02])  # NaN does not count in m
    assert out[0] == pytest.approx(0.02) and math.isnan(out[1]) and out[2] == pytest.approx(0.02)


def test_verdict_words() -> None:
    # 1, 2, 3: interval 2 +- 2.484 = [-0.484, 4.484]
    iv = interval([1.0, 2.0, 3.0])
    assert judge(iv, -1.0).outcome is Outcome.HOLDS and str(judge(iv, -1.0)) == "holds"
    assert str(judge(iv, 5.0)) == "refuted (effect excluded at 95%)"
    assert str(judge(iv, 0.0)) == "not significant at n = 3 (smallest detectable effect 3.1)"
    assert judge(iv, 5.0, side="below").holds
    assert str(judge(interval([4.0]))) == "cannot judge (n = 1 < 2)"
    assert str(judge(iv, -1.0, min_n=4)) == "cannot judge (n = 3 < 4)"
    # an interval with no spread: the p-value is 0 off the bound
    flat = Interval(1.0, 0.0, 3, 0.0, 2.0)
    assert judge(flat, 0.0).holds and judge(flat, 0.0).p == 0.0


def test_holm_turns_a_weak_verdict_in_a_family_into_not_significant() -> None:
    # Prepare: 10, 12, 14 against 0: t = 12/1.1547 = 10.392, df 2: p = 1 - t/sqrt(2 + t^2)
    # = 1 - 10.392/10.488 = 0.00914; 1, 2, 3 against -1: t = 3/0.57735 = 5.196, p = 1 -
    # 5.196/sqrt(29) = 0.03510. Each holds alone.
    strong, weak = judge(interval([10.0, 12.0, 14.0])), judge(interval([1.0, 2.0, 3.0]), -1.0)
    assert strong.p == pytest.approx(0.00914, abs=1e-5) and weak.p == pytest.approx(
        0.03510, abs=1e-5
    )
    assert strong.holds and weak.holds
    # Execute: a family of three (strong, weak, weak): Holm multiplies the sorted p-values by
    # 3, 2, 1: 0.0274, 0.0702, 0.0351 -> running maximum 0.0274, 0.0702, 0.0702
    s, w1, w2 = adjust([strong, weak, weak])
    # Assert
    assert s.holds and s.p_adjusted == pytest.approx(0.02743, abs=1e-4)
    for w in (w1, w2):
        assert w.outcome is Outcome.NOT_SIGNIFICANT and w.p_adjusted == pytest.approx(
            0.07020, abs=1e-4
        )
        assert str(w).startswith("not significant at n = 3")
    # in a family of two, the second p-value is multiplied by 1: both hold
    assert all(j.holds for j in adjust([strong, weak]))
