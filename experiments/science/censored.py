"""Times to a target that some runs never reach (censored at their budget): Kaplan-Meier
survival and medians, a median's bootstrap interval and the ratio of two groups' medians
(:class:`CensoredRatio`, which :func:`~.statistics.judge` takes as it takes an interval).
A run that never reached the target only says its time exceeds the budget: it is never
counted as reaching it there.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from dfrl.experiments.science.statistics import (
    LEVEL,
    POWER,
    BootstrapInterval,
    checked_values,
    normal_quantile,
)


# -- censored times to a target ----------------------------------------------------------------
def _censored(times: Sequence[float], reached: Sequence[bool]) -> tuple[np.ndarray, np.ndarray]:
    t, ev = np.asarray(checked_values(times)), np.asarray([bool(r) for r in reached], dtype=bool)
    if len(ev) != len(t):
        raise ValueError(f"{len(t)} times and {len(ev)} reached flags")
    return t, ev


def _km_steps(t: np.ndarray, ev: np.ndarray) -> Iterator[tuple[float, float]]:
    s = 1.0
    for u in np.unique(t[ev]):
        s *= 1.0 - np.count_nonzero(ev & (t == u)) / np.count_nonzero(t >= u)
        yield float(u), float(s)


def kaplan_meier(times: Sequence[float], reached: Sequence[bool]) -> list[tuple[float, float]]:
    """The Kaplan-Meier estimate of P(time to target > t) from right-censored times: a run that
    reached the target at ``times[i]`` (``reached[i]``) is an event there, one that never did is
    known only to take longer than ``times[i]`` (its budget). At each event time u, with d
    events and n runs whose time is >= u (a run censored at u still counts at u),
    S(u) = S(u-) x (1 - d / n). Returns the steps ``[(u, S(u)), ...]`` in time order."""
    return list(_km_steps(*_censored(times, reached)))


def _median(t: np.ndarray, ev: np.ndarray) -> float:
    return next((u for u, s in _km_steps(t, ev) if s <= 0.5), math.inf)


def km_median(times: Sequence[float], reached: Sequence[bool]) -> float:
    """The Kaplan-Meier median: the first event time u with S(u) <= 1/2; ``inf`` when the curve
    stays above 1/2 (the median lies beyond the budget)."""
    return _median(*_censored(times, reached))


def _bounds(t: np.ndarray, ev: np.ndarray) -> tuple[float, float]:
    """What the runs say of the median: (m, m), or (largest time, inf) when it lies beyond."""
    m = _median(t, ev)
    return (m, m) if math.isfinite(m) else (float(t.max()), math.inf)


def _resampled(t: np.ndarray, ev: np.ndarray, rng: np.random.Generator, k: int) -> np.ndarray:
    """Median bounds of ``k`` resamples with replacement, shape (k, 2)."""
    return np.array([_bounds(t[i], ev[i]) for i in rng.integers(0, len(t), (k, len(t)))])


def _ends(low: np.ndarray, high: np.ndarray) -> tuple[float, float]:
    tail = (1.0 - LEVEL) / 2.0
    return (
        float(np.quantile(low, tail, method="lower")),
        float(np.quantile(high, 1.0 - tail, method="higher")),
    )


@dataclass(frozen=True)
class CensoredRatio(BootstrapInterval):
    """``median_a / median_b`` of censored times (Kaplan-Meier medians) with its 95% percentile
    bootstrap interval (:func:`censored_ratio`). A median beyond the budget only exceeds the
    group's largest time, so the ratio is a bound: ``known`` is ``exact``, ``at least`` (a's
    beyond), ``at most`` (b's) or ``unknown`` (both; ``estimate`` NaN). ``draws`` (k, 2): the
    lowest and highest ratio each resample allows, giving ``low`` and ``high``, so a censored
    median never counts for a claim. :func:`judge` takes it as an :class:`Interval`."""

    n: int
    known: str
    draws: np.ndarray = field(repr=False, compare=False)

    @property
    def half(self) -> float:
        return (self.high - self.low) / 2.0

    def p_value(self, null: float = 1.0) -> float:
        """Two-sided p of "the ratio is ``null``": twice the smaller share of resamples that
        allow a ratio on one side of it, at most 1."""
        below, above = np.mean(self.draws[:, 0] <= null), np.mean(self.draws[:, 1] >= null)
        return float(min(1.0, 2.0 * min(below, above)))

    def detectable(self, power: float = POWER) -> float:
        """The smallest factor the true ratio must differ from the null by for a 5% test of this
        spread to see it with ``power``: exp((z(0.975) + z(power)) se), se of the log ratio =
        its interval's width / (2 x 1.96); ``inf`` for an open interval."""
        if not (0.0 < self.low and math.isfinite(self.high)):
            return math.inf
        se = (math.log(self.high) - math.log(self.low)) / (2.0 * normal_quantile(0.975))
        return math.exp((normal_quantile(0.975) + normal_quantile(power)) * se)

    def __str__(self) -> str:
        sign = {"at least": ">= ", "at most": "<= "}.get(self.known, "")
        return f"{sign}{self.estimate:.3g} [{self.low:.3g}, {self.high:.3g}]"


def _span(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest ratio ``a / b`` of median bounds (columns low, high)."""
    with np.errstate(divide="ignore"):
        return a[..., 0] / b[..., 1], a[..., 1] / b[..., 0]


def censored_ratio(
    a: tuple[Sequence[float], Sequence[bool]],
    b: tuple[Sequence[float], Sequence[bool]],
    resamples: int = 4000,
    seed: int = 0,
) -> CensoredRatio:
    """The ratio of Kaplan-Meier medians ``a / b`` (e.g. T(1) / T(N)) of two independent groups
    of ``(times, reached)``: each group's runs resampled with replacement on their own
    (generator seeded with ``seed``), censored runs staying censored (none is set to the
    budget); the percentile interval of the lowest and highest ratios the resamples allow."""
    rng = np.random.default_rng(seed)
    (ta, ea), (tb, eb) = _censored(*a), _censored(*b)
    ba, bb = np.array(_bounds(ta, ea)), np.array(_bounds(tb, eb))
    lo, hi = _span(ba, bb)
    known = {
        (True, True): "exact",
        (False, True): "at least",
        (True, False): "at most",
        (False, False): "unknown",
    }[(ba[0] == ba[1], bb[0] == bb[1])]
    est = {"exact": lo, "at least": lo, "at most": hi}.get(known, math.nan)
    low, high = _span(_resampled(ta, ea, rng, resamples), _resampled(tb, eb, rng, resamples))
    return CensoredRatio(
        float(est),
        *_ends(low, high),
        resamples,
        "percentile",
        min(len(ta), len(tb)),
        known,
        np.stack([low, high], axis=1),
    )


def km_median_interval(
    times: Sequence[float], reached: Sequence[bool], resamples: int = 4000, seed: int = 0
) -> BootstrapInterval:
    """The Kaplan-Meier median (``inf`` beyond the budget) with its 95% percentile bootstrap
    interval (a resample whose median lies beyond gives its largest time to ``low`` and
    ``inf`` to ``high``)."""
    t, ev = _censored(times, reached)
    d = _resampled(t, ev, np.random.default_rng(seed), resamples)
    return BootstrapInterval(_median(t, ev), *_ends(d[:, 0], d[:, 1]), resamples, "percentile")
