"""The statistics of the reports and the studies, done once: Student-t intervals (one sample,
paired, Welch), bootstrap intervals, times to a target that some runs never reach
(Kaplan-Meier medians and their ratio: :mod:`.censored`), Holm's correction, the smallest
detectable effect and the verdict words every report uses. Pure functions of numbers;
:mod:`.report` and :mod:`.studies` both use them. Student's t, the normal distribution and
the bootstrap come from ``scipy.stats`` (``science/README.md``, "Dependencies"); how they
combine is ours.

The verdict of a claim "the mean is above (below) a bound" (:func:`judge`): ``holds`` (the 95%
interval lies wholly on the claimed side and, in a family, the Holm-adjusted p-value is below
5%: :func:`adjust`); ``refuted (effect excluded at 95%)`` (it lies wholly on the other side or
touches the bound from there); ``not significant at n = K (smallest detectable effect D)``
(neither; D is the true distance from the bound a 5% test at this n and spread finds with 80%
power); ``cannot judge (n = K < M)`` (too few values).
"""

from __future__ import annotations

from typing import Protocol

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np


def _stats():  # noqa: ANN202 - the module scipy.stats
    """``scipy.stats``, imported when a statistic is first computed: importing it costs about
    0.4 s, which every ``dfrl`` command would otherwise pay while it builds its parser."""
    from scipy import stats

    return stats


#: Two-sided level of every interval and verdict.
LEVEL: float = 0.95
#: Power at which the smallest detectable effect is stated.
POWER: float = 0.8


# -- Student's t and the normal distribution -------------------------------------------------
def t_cdf(t: float, df: float) -> float:
    """P(T <= t) for Student's t with ``df`` > 0 degrees of freedom (not necessarily whole)."""
    if df <= 0:
        raise ValueError(f"degrees of freedom must be > 0, got {df}")
    return float(_stats().t.cdf(t, df))


def t_quantile(p: float, df: float) -> float:
    """The ``p`` quantile of Student's t with ``df`` degrees of freedom."""
    if not (0.0 < p < 1.0 and df > 0):
        raise ValueError(f"a quantile needs 0 < p < 1 and df > 0, got p = {p}, df = {df}")
    return float(_stats().t.ppf(p, df))


def t975(df: float) -> float:
    """The 97.5% quantile of Student's t (the multiplier of a 95% two-sided interval)."""
    if df < 1:
        raise ValueError("an interval needs at least two values")
    return t_quantile(0.975, float(df))


def normal_quantile(p: float) -> float:
    """The ``p`` quantile of the standard normal distribution."""
    return float(_stats().norm.ppf(p))


# -- means and intervals over seeds ----------------------------------------------------------
@dataclass(frozen=True)
class Interval:
    """A mean (or mean difference) of ``n`` values with its 95% t interval.

    ``half`` is the half width (nan for n < 2), ``se`` the standard error and ``df`` the
    degrees of freedom it was computed with (Welch's are not whole)."""

    mean: float
    half: float
    n: int
    se: float = float("nan")
    df: float = float("nan")

    @property
    def low(self) -> float:
        return self.mean - self.half

    @property
    def high(self) -> float:
        return self.mean + self.half

    def excludes(self, value: float) -> bool:
        """The interval lies wholly above or below ``value``."""
        return not math.isnan(self.half) and (self.low > value or self.high < value)

    def p_value(self, null: float = 0.0) -> float:
        """Two-sided p-value of the t test of "the mean is ``null``" (nan for n < 2; with
        no spread, 0 when the mean differs from ``null`` and 1 when it equals it)."""
        if math.isnan(self.se) or math.isnan(self.df):
            return float("nan")
        if self.se == 0.0:
            return 1.0 if self.mean == null else 0.0
        t = abs(self.mean - null) / self.se
        return 2.0 * (1.0 - t_cdf(t, self.df))

    def detectable(self, power: float = POWER) -> float:
        """The smallest true distance from the null that a two-sided 5% t test with this
        standard error and df detects with probability ``power``:
        ``(t(0.975, df) + t(power, df)) x se`` (nan for n < 2)."""
        if math.isnan(self.se) or math.isnan(self.df):
            return float("nan")
        return (t975(self.df) + t_quantile(power, self.df)) * self.se

    def __str__(self) -> str:
        if math.isnan(self.half):
            return f"{self.mean:.3g} (n={self.n})"
        return f"{self.mean:.3g} ± {self.half:.2g} (n={self.n})"


def checked_values(values: Sequence[float]) -> list[float]:
    """``values`` as floats.

    Raises
    ------
    ValueError
        No values, or a NaN among them.
    """
    xs = [float(v) for v in values]
    if not xs:
        raise ValueError("no values")
    if any(math.isnan(x) for x in xs):
        raise ValueError(f"NaN among the values: {xs}")
    return xs


def interval(values: Sequence[float]) -> Interval:
    """Mean and 95% t interval of ``values`` (df = n - 1; NaNs are an error, not dropped)."""
    xs = checked_values(values)
    n = len(xs)
    mean = sum(xs) / n
    if n < 2:
        return Interval(mean, float("nan"), n)
    var = sum((x - mean) ** 2 for x in xs) / (n - 1)
    se = math.sqrt(var / n)
    return Interval(mean, t975(n - 1) * se, n, se, float(n - 1))


def paired(a: Sequence[float], b: Sequence[float]) -> Interval:
    """Mean of the differences ``a[i] - b[i]`` of paired values (e.g. the same seed under two
    conditions) with its 95% t interval (df = n - 1)."""
    xa, xb = checked_values(a), checked_values(b)
    if len(xa) != len(xb):
        raise ValueError(f"paired values need equal lengths, got {len(xa)} and {len(xb)}")
    return interval([x - y for x, y in zip(xa, xb)])


def welch(a: Sequence[float], b: Sequence[float]) -> Interval:
    """Mean difference ``a - b`` of two independent samples with Welch's 95% interval: standard
    error sqrt(va/na + vb/nb), Welch-Satterthwaite degrees of freedom
    (va/na + vb/nb)^2 / ((va/na)^2/(na-1) + (vb/nb)^2/(nb-1)). ``n`` is the smaller sample."""
    xa, xb = checked_values(a), checked_values(b)
    na, nb = len(xa), len(xb)
    ma, mb = sum(xa) / na, sum(xb) / nb
    if na < 2 or nb < 2:
        return Interval(ma - mb, float("nan"), min(na, nb))
    va = sum((x - ma) ** 2 for x in xa) / (na - 1) / na
    vb = sum((x - mb) ** 2 for x in xb) / (nb - 1) / nb
    se = math.sqrt(va + vb)
    if se == 0.0:
        return Interval(ma - mb, 0.0, min(na, nb), 0.0, float(na + nb - 2))
    df = (va + vb) ** 2 / (va**2 / (na - 1) + vb**2 / (nb - 1))
    return Interval(ma - mb, t975(df) * se, min(na, nb), se, df)


# -- bootstrap -------------------------------------------------------------------------------
@dataclass(frozen=True)
class BootstrapInterval:
    """A statistic of the data with its 95% bootstrap interval."""

    estimate: float
    low: float
    high: float
    resamples: int
    method: str

    def excludes(self, value: float) -> bool:
        return self.low > value or self.high < value

    def __str__(self) -> str:
        return f"{self.estimate:.3g} [{self.low:.3g}, {self.high:.3g}]"


def bootstrap(
    samples: Sequence[Sequence[float]],
    statistic: Callable[..., float],
    resamples: int = 10_000,
    seed: int = 0,
    method: str = "bca",
) -> BootstrapInterval:
    """95% bootstrap interval of ``statistic(*samples)`` (``scipy.stats.bootstrap``): each
    sample resampled with replacement on its own, ``resamples`` times, from a generator seeded
    with ``seed``; ``method`` ``percentile`` or ``bca`` (Efron 1987), percentile (and
    ``method`` says so) where BCa is undefined, e.g. constant data. A ratio of means:
    ``bootstrap([t1, tn], lambda a, b: a.mean() / b.mean())``."""
    if method not in ("percentile", "bca"):
        raise ValueError(f"method: percentile or bca, got {method!r}")
    data = [np.asarray(checked_values(s), dtype=np.float64) for s in samples]
    if not data:
        raise ValueError("no samples")
    est = float(statistic(*data))

    def once(*resampled: np.ndarray) -> float:
        return float(statistic(*resampled))

    def run(how: str) -> tuple[float, float]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # degenerate data: NaN, handled below
            res = _stats().bootstrap(
                data,
                once,
                n_resamples=resamples,
                vectorized=False,
                paired=False,
                confidence_level=LEVEL,
                method=how,
                rng=np.random.default_rng(seed),
            )
        return float(res.confidence_interval.low), float(res.confidence_interval.high)

    used = method
    low, high = run("BCa" if method == "bca" else "percentile")
    if method == "bca" and not (math.isfinite(low) and math.isfinite(high)):
        used = "percentile"
        low, high = run("percentile")
    return BootstrapInterval(est, low, high, resamples, used)


# -- multiplicity ----------------------------------------------------------------------------
def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of a family of p-values, in the order given: the i-th
    smallest of m becomes max over j <= i of (m - j + 1) p_(j), capped at 1. A claim holds
    at family-wise level 5% when its adjusted p-value is below 0.05. NaNs stay NaN and do
    not count in m."""
    ps = [float(p) for p in p_values]
    order = sorted((i for i, p in enumerate(ps) if not math.isnan(p)), key=lambda i: ps[i])
    m = len(order)
    out = [float("nan")] * len(ps)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * ps[i]))
        out[i] = running
    return out


# -- verdicts --------------------------------------------------------------------------------
class Outcome(Enum):
    """The four verdicts of a claim about a mean."""

    HOLDS = "holds"
    REFUTED = "refuted"
    NOT_SIGNIFICANT = "not significant"
    CANNOT_JUDGE = "cannot judge"


#: Fewest values a verdict is given on (below: cannot judge).
MIN_N: int = 2


@dataclass(frozen=True)
class Judgement:
    """The verdict on "the mean of ``measure`` is ``side`` ``bound``".

    ``p`` is the two-sided t test's p-value against the bound, ``p_adjusted`` the Holm-adjusted
    one once :func:`adjust` put it in a family (else equal to ``p``)."""

    outcome: Outcome
    measure: Measured
    bound: float
    side: str
    p: float
    p_adjusted: float
    min_n: int = MIN_N

    @property
    def holds(self) -> bool:
        return self.outcome is Outcome.HOLDS

    def words(self) -> str:
        """The verdict in the report's words."""
        if self.outcome is Outcome.REFUTED:
            return "refuted (effect excluded at 95%)"
        if self.outcome is Outcome.NOT_SIGNIFICANT:
            return (
                f"not significant at n = {self.measure.n} (smallest detectable effect "
                f"{self.measure.detectable():.2g})"
            )
        if self.outcome is Outcome.CANNOT_JUDGE:
            return f"cannot judge (n = {self.measure.n} < {self.min_n})"
        return "holds"

    def __str__(self) -> str:
        return self.words()


class Measured(Protocol):
    """What :func:`judge` and a :class:`Judgement` read of an interval: an :class:`Interval`,
    or another estimate with the same reading (a transfer claim's censored difference)."""

    @property
    def half(self) -> float: ...

    @property
    def n(self) -> int: ...

    @property
    def low(self) -> float: ...

    @property
    def high(self) -> float: ...

    def p_value(self, null: float = 0.0) -> float: ...

    def detectable(self, power: float = POWER) -> float: ...


def judge(
    measure: Measured, bound: float = 0.0, side: str = "above", min_n: int = MIN_N
) -> Judgement:
    """The verdict on "the mean is above (``side="above"``) or below ``bound``", from the 95%
    interval ``measure`` (see the module's docs for the words)."""
    if side not in ("above", "below"):
        raise ValueError(f"side: above or below, got {side!r}")
    p = measure.p_value(bound)
    if measure.n < max(min_n, 2) or math.isnan(measure.half):
        return Judgement(Outcome.CANNOT_JUDGE, measure, bound, side, p, p, min_n)
    lo, hi = measure.low, measure.high
    if (lo > bound) if side == "above" else (hi < bound):
        outcome = Outcome.HOLDS
    elif (hi <= bound) if side == "above" else (lo >= bound):
        outcome = Outcome.REFUTED
    else:
        outcome = Outcome.NOT_SIGNIFICANT
    return Judgement(outcome, measure, bound, side, p, p, min_n)


def adjust(family: Sequence[Judgement], level: float = 1.0 - LEVEL) -> list[Judgement]:
    """The verdicts of a family with Holm-adjusted p-values: a verdict that held alone holds
    in the family only if its adjusted p-value is below ``level``, otherwise it becomes "not
    significant" (refutations and the rest are kept: each is about one interval)."""
    adj = holm([j.p for j in family])
    out = []
    for j, p in zip(family, adj):
        outcome = j.outcome
        if outcome is Outcome.HOLDS and not p < level:
            outcome = Outcome.NOT_SIGNIFICANT
        out.append(replace(j, outcome=outcome, p_adjusted=p))
    return out
