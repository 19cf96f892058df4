"""The statistics of the reports and the studies, done once: learning-curve measures, Student-t
intervals (one sample, paired, Welch), bootstrap intervals, Holm's correction, the smallest
detectable effect, and the verdict words every report uses.

Pure functions of numbers and arrays; :mod:`.report` (the paper's observations and figures)
and :mod:`.studies` (sweep, speed-up, transfer) both use them, neither imports the other.
Standard library and numpy only: Student's t comes from the regularised incomplete beta
function (:func:`t_cdf`, :func:`t_quantile`), the normal quantile from
:class:`statistics.NormalDist` (why not scipy: ``science/README.md``, "Dependencies").

The verdict of a claim "the mean is above (below) a bound" (:func:`judge`) is one of

* ``holds``: the 95% interval lies wholly on the claimed side (and, in a family of verdicts,
  the Holm-adjusted p-value is below 5%: :func:`adjust`);
* ``refuted (effect excluded at 95%)``: the interval lies wholly on the other side (or touches
  the bound from there), so every effect in the claimed direction is excluded;
* ``not significant at n = K (smallest detectable effect D)``: neither; D is the true distance
  from the bound that a test at this n and spread would find with 80% power at the 5% level;
* ``cannot judge (n = K < M)``: too few values.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from enum import Enum
from functools import lru_cache
from statistics import NormalDist

import numpy as np

#: Two-sided level of every interval and verdict.
LEVEL: float = 0.95
#: Power at which the smallest detectable effect is stated.
POWER: float = 0.8


# -- learning curves -------------------------------------------------------------------------
def smooth(y: np.ndarray, window: int = 200) -> np.ndarray:
    """Moving average (same length; the window shrinks at the start)."""
    y = np.asarray(y, dtype=np.float64)
    if len(y) == 0 or window <= 1:
        return y
    c = np.cumsum(np.insert(y, 0, 0.0))
    idx = np.arange(1, len(y) + 1)
    lo = np.maximum(0, idx - window)
    return (c[idx] - c[lo]) / (idx - lo)


def t_fraction(it: np.ndarray, y: np.ndarray, frac: float = 0.9) -> int:
    """First iteration at which the (smoothed) curve reaches ``frac`` of its final value."""
    ys = smooth(y)
    final = ys[-1]
    if final <= 0:
        return int(it[-1])
    hit = np.nonzero(ys >= frac * final)[0]
    return int(it[hit[0]]) if len(hit) else int(it[-1])


def late_growth(y: np.ndarray) -> float:
    """Growth over the last quarter as a fraction of the total growth (small: saturated)."""
    ys = smooth(y)
    n = len(ys)
    total = ys[-1] - ys[0]
    if n < 4 or total == 0:
        return float("nan")
    return float((ys[-1] - ys[int(0.75 * n)]) / total)


def reward_rate(y: np.ndarray, part: str) -> float:
    """Mean reward per iteration over the first or last quarter of a cumulative curve."""
    n = len(y)
    q = max(1, n // 4)
    if part == "first":
        return float(y[q - 1] / q)
    return float((y[-1] - y[n - q - 1]) / q)


def dip(y: np.ndarray) -> tuple[float, int]:
    """Largest drop of the smoothed curve below its running peak, as a fraction of that peak,
    and the iteration index where it bottoms."""
    ys = smooth(y, 100)
    peak = np.maximum.accumulate(ys)
    with np.errstate(divide="ignore", invalid="ignore"):
        drop = np.where(peak > 0, (peak - ys) / peak, 0.0)
    k = int(np.argmax(drop))
    return float(drop[k]), k




# -- Student's t and the normal distribution -------------------------------------------------
def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the regularised incomplete beta function (modified Lentz)."""
    tiny, eps = 1e-300, 1e-15
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 400):
        m2 = 2 * m
        for num in (m * (b - m) * x / ((a + m2 - 1.0) * (a + m2)),
                    -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1.0))):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < eps:
            break
    return h


def incomplete_beta(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b), for a, b > 0 and 0 <= x <= 1."""
    if not 0.0 <= x <= 1.0:
        raise ValueError(f"x = {x} is outside [0, 1]")
    if x in (0.0, 1.0):
        return x
    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b)
                     + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _betacf(a, b, x) / a
    return 1.0 - front * _betacf(b, a, 1.0 - x) / b


def t_cdf(t: float, df: float) -> float:
    """P(T <= t) for Student's t with ``df`` > 0 degrees of freedom (not necessarily whole)."""
    if df <= 0:
        raise ValueError(f"degrees of freedom must be > 0, got {df}")
    if math.isinf(t):
        return 1.0 if t > 0 else 0.0
    tail = 0.5 * incomplete_beta(df / 2.0, 0.5, df / (df + t * t))    # P(T > |t|)
    return 1.0 - tail if t > 0 else tail


@lru_cache(maxsize=4096)
def t_quantile(p: float, df: float) -> float:
    """The ``p`` quantile of Student's t with ``df`` degrees of freedom (bisection on
    :func:`t_cdf` to 1e-10)."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"a quantile needs 0 < p < 1, got {p}")
    if p < 0.5:
        return -t_quantile(1.0 - p, df)
    lo, hi = 0.0, 2.0
    while t_cdf(hi, df) < p:
        lo, hi = hi, 2.0 * hi
    while hi - lo > 1e-10 * max(1.0, hi):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if t_cdf(mid, df) < p else (lo, mid)
    return 0.5 * (lo + hi)


def t975(df: float) -> float:
    """The 97.5% quantile of Student's t (the multiplier of a 95% two-sided interval)."""
    if df < 1:
        raise ValueError("an interval needs at least two values")
    return t_quantile(0.975, float(df))


def normal_quantile(p: float) -> float:
    """The ``p`` quantile of the standard normal distribution."""
    return NormalDist().inv_cdf(p)


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


def _values(values: Sequence[float]) -> list[float]:
    xs = [float(v) for v in values]
    if not xs:
        raise ValueError("no values")
    if any(math.isnan(x) for x in xs):
        raise ValueError(f"NaN among the values: {xs}")
    return xs


def interval(values: Sequence[float]) -> Interval:
    """Mean and 95% t interval of ``values`` (df = n - 1; NaNs are an error, not dropped)."""
    xs = _values(values)
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
    xa, xb = _values(a), _values(b)
    if len(xa) != len(xb):
        raise ValueError(f"paired values need equal lengths, got {len(xa)} and {len(xb)}")
    return interval([x - y for x, y in zip(xa, xb)])


def welch(a: Sequence[float], b: Sequence[float]) -> Interval:
    """Mean difference ``a - b`` of two independent samples with Welch's 95% interval: standard
    error sqrt(va/na + vb/nb), Welch-Satterthwaite degrees of freedom
    (va/na + vb/nb)^2 / ((va/na)^2/(na-1) + (vb/nb)^2/(nb-1)). ``n`` is the smaller sample."""
    xa, xb = _values(a), _values(b)
    na, nb = len(xa), len(xb)
    ma, mb = sum(xa) / na, sum(xb) / nb
    if na < 2 or nb < 2:
        return Interval(ma - mb, float("nan"), min(na, nb))
    va = sum((x - ma) ** 2 for x in xa) / (na - 1) / na
    vb = sum((x - mb) ** 2 for x in xb) / (nb - 1) / nb
    se = math.sqrt(va + vb)
    if se == 0.0:
        return Interval(ma - mb, 0.0, min(na, nb), 0.0, float(na + nb - 2))
    df = (va + vb) ** 2 / (va ** 2 / (na - 1) + vb ** 2 / (nb - 1))
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


def jackknife_acceleration(samples: Sequence[np.ndarray],
                           statistic: Callable[..., float]) -> float:
    """BCa's acceleration: with the leave-one-out values theta_i of the statistic (one value
    left out of one sample at a time, over every sample) and their mean m,
    ``sum((m - theta_i)^3) / (6 (sum((m - theta_i)^2))^1.5)`` (0 when they are all equal)."""
    loo = []
    for k, s in enumerate(samples):
        for i in range(len(s)):
            rest = [np.delete(s, i) if j == k else t for j, t in enumerate(samples)]
            loo.append(float(statistic(*rest)))
    d = np.mean(loo) - np.asarray(loo)
    den = 6.0 * float(np.sum(d ** 2)) ** 1.5
    return float(np.sum(d ** 3)) / den if den > 0 else 0.0


def bootstrap(samples: Sequence[Sequence[float]], statistic: Callable[..., float],
              resamples: int = 10_000, seed: int = 0, method: str = "bca") -> BootstrapInterval:
    """95% bootstrap interval of ``statistic(*samples)``: every sample is resampled with
    replacement on its own (independent groups), ``resamples`` times, from a generator seeded
    with ``seed``. ``method``: ``percentile`` (the 2.5% and 97.5% quantiles of the resampled
    statistics) or ``bca`` (bias-corrected and accelerated, Efron 1987: the quantiles at
    Phi(z0 + (z0 + z)/(1 - a (z0 + z))) for z = Phi^-1(0.025), Phi^-1(0.975), with z0 =
    Phi^-1(share of resampled values below the estimate) and a from
    :func:`jackknife_acceleration`). E.g. a ratio of means: ``bootstrap([t1, tn],
    lambda a, b: a.mean() / b.mean())``.
    """
    if method not in ("percentile", "bca"):
        raise ValueError(f"method: percentile or bca, got {method!r}")
    data = [np.asarray(_values(s), dtype=np.float64) for s in samples]
    if not data:
        raise ValueError("no samples")
    est = float(statistic(*data))
    rng = np.random.default_rng(seed)
    idx = [rng.integers(0, len(s), size=(resamples, len(s))) for s in data]
    boot = np.array([statistic(*(s[i[r]] for s, i in zip(data, idx))) for r in range(resamples)],
                    dtype=np.float64)
    alpha = (1.0 - LEVEL) / 2.0
    qs = [alpha, 1.0 - alpha]
    if method == "bca":
        below = float(np.mean(boot < est)) + 0.5 * float(np.mean(boot == est))
        if 0.0 < below < 1.0:
            z0 = normal_quantile(below)
            a = jackknife_acceleration(data, statistic)
            qs = [NormalDist().cdf(z0 + (z0 + z) / (1.0 - a * (z0 + z)))
                  for z in (normal_quantile(q) for q in qs)]
    low, high = np.quantile(boot, qs)
    return BootstrapInterval(est, float(low), float(high), resamples, method)


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
    measure: Interval
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
            return (f"not significant at n = {self.measure.n} (smallest detectable effect "
                    f"{self.measure.detectable():.2g})")
        if self.outcome is Outcome.CANNOT_JUDGE:
            return f"cannot judge (n = {self.measure.n} < {self.min_n})"
        return "holds"

    def __str__(self) -> str:
        return self.words()


def judge(measure: Interval, bound: float = 0.0, side: str = "above",
          min_n: int = MIN_N) -> Judgement:
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
