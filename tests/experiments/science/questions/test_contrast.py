"""A paired contrast's interval, verdict and power (scipy and statsmodels underneath), on
numbers worked by hand."""

import math

import pytest

from dfrl.experiments.science.questions.contrast import Contrast, Outcome, judge_family


def _c(a, b, side="above", delta=0.1):
    return Contrast(tuple(range(1, len(a) + 1)), tuple(a), tuple(b), side, delta)


def test_interval_and_p_by_hand():
    # differences 1, 2, 3: mean 2, sd 1, se 1/sqrt(3), t(0.975, 2) = 4.302653
    c = _c([1, 2, 3], [0, 0, 0])
    low, high = c.interval()
    half = 4.302653 / math.sqrt(3)
    assert (low, high) == pytest.approx((2 - half, 2 + half), abs=1e-5)
    # one-sided p of t = 2 sqrt 3 with 2 df: (1 - t / sqrt(t^2 + 2)) / 2 = 0.0370900
    assert c.p == pytest.approx(0.0370900, abs=1e-6)


def test_zero_spread_cannot_be_judged_never_a_verdict():
    c = _c([0.5, 0.5, 0.5, 0.5], [0.0, 0.0, 0.0, 0.0])
    (j,) = judge_family([c])
    assert j.outcome is Outcome.CANNOT_JUDGE and "same difference" in j.reason
    assert math.isnan(j.p_adjusted) and all(math.isnan(x) for x in c.interval())


def test_too_few_seeds_cannot_be_judged():
    (j,) = judge_family([_c([1.0, 0.9], [0.0, 0.1])])
    assert j.outcome is Outcome.CANNOT_JUDGE and "n = 2" in j.words()


def test_holds_refuted_and_not_significant():
    big = _c([0.9, 0.95, 0.85, 0.92, 0.88], [0.0, 0.05, -0.02, 0.01, 0.0])
    small = _c([0.01, 0.02, -0.01, 0.0, 0.015], [0.0, 0.0, 0.0, 0.0, 0.0])
    noisy = _c([0.5, -0.4, 0.3, -0.2, 0.1], [0.0, 0.0, 0.0, 0.0, 0.0])
    j = judge_family([big, small, noisy])
    assert [x.outcome for x in j] == [Outcome.HOLDS, Outcome.REFUTED, Outcome.NOT_SIGNIFICANT]
    assert "smallest detectable effect" in j[2].words()
    assert j[2].contrast.detectable() > 0.1 > j[0].contrast.detectable()


def test_holm_within_the_family_can_take_a_verdict_away():
    # alone p = 0.037 holds; beside two rows with the same p Holm makes each 3p = 0.11
    a = _c([0.12, 0.25, -0.02, 0.15, 0.05], [0.0] * 5)
    (alone,) = judge_family([a])
    three = judge_family([a, a, a])
    assert alone.outcome is Outcome.HOLDS
    assert alone.contrast.p < 0.05 < three[0].p_adjusted
    assert all(x.outcome is not Outcome.HOLDS for x in three)


def test_two_sided_says_which_side():
    c = _c([0.0, 0.05, -0.02, 0.01, 0.0], [0.9, 0.95, 0.85, 0.92, 0.88], side="two-sided")
    (j,) = judge_family([c])
    assert j.outcome is Outcome.HOLDS and j.words() == "holds (B higher)"


def test_a_veto_is_cannot_judge_and_leaves_the_family():
    a = _c([0.12, 0.2, 0.05, 0.15, 0.1], [0.0] * 5)
    j = judge_family([a, a], ["its control learns", ""])
    assert j[0].outcome is Outcome.CANNOT_JUDGE and "its control learns" in j[0].words()
    assert j[1].p_adjusted == pytest.approx(j[1].contrast.p)  # a family of one


def test_power_falls_with_n_and_seeds_needed_reaches_delta():
    c = _c([0.3, 0.1, 0.2, 0.0, 0.25], [0.0] * 5, delta=0.05)
    n = c.seeds_needed()
    assert n is not None and n > 5
    at = Contrast(tuple(range(n)), tuple([0.0] * n), tuple([0.0] * n), "above", 0.05)

    # the same spread at n and n - 1 pairs: D(n) <= delta < D(n - 1)
    def d(k):
        return c._effect_size(k) * c.sd

    assert d(n) <= 0.05 < d(n - 1)
    assert at.n == n


def test_bad_contrasts_are_refused():
    with pytest.raises(ValueError, match="one value per seed"):
        Contrast((1, 2), (0.1,), (0.0, 0.0), "above", 0.1)
    with pytest.raises(ValueError, match="side"):
        _c([1, 2, 3], [0, 0, 0], side="up")
    with pytest.raises(ValueError, match="delta"):
        _c([1, 2, 3], [0, 0, 0], delta=0)
