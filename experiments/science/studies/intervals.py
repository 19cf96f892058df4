"""Means with 95% Student-t confidence intervals, for results over a few seeds."""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

#: Two-sided 95% quantiles of Student's t, by degrees of freedom 1..30.
_T975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
         2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
         2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042)


def t975(df: int) -> float:
    """The 97.5% quantile of Student's t with ``df`` degrees of freedom (table to 30, then
    the normal approximation with a 1/df correction, within 0.5% of the exact value)."""
    if df < 1:
        raise ValueError("an interval needs at least two values")
    if df <= len(_T975):
        return _T975[df - 1]
    return 1.959964 + 2.4 / df


@dataclass(frozen=True)
class Interval:
    """Mean of ``n`` values with the half width of its 95% t interval (nan for n < 2)."""

    mean: float
    half: float
    n: int

    @property
    def low(self) -> float:
        return self.mean - self.half

    @property
    def high(self) -> float:
        return self.mean + self.half

    def excludes(self, value: float) -> bool:
        """The interval lies wholly above or below ``value``."""
        return not math.isnan(self.half) and (self.low > value or self.high < value)

    def __str__(self) -> str:
        if math.isnan(self.half):
            return f"{self.mean:.3g} (n={self.n})"
        return f"{self.mean:.3g} ± {self.half:.2g} (n={self.n})"


def interval(values: Sequence[float]) -> Interval:
    """Mean and 95% t interval of ``values`` (NaNs are an error, not dropped)."""
    xs = [float(v) for v in values]
    if not xs:
        raise ValueError("no values")
    if any(math.isnan(x) for x in xs):
        raise ValueError(f"NaN among the values: {xs}")
    n = len(xs)
    mean = sum(xs) / n
    if n < 2:
        return Interval(mean, float("nan"), n)
    var = sum((x - mean) ** 2 for x in xs) / (n - 1)
    return Interval(mean, t975(n - 1) * math.sqrt(var / n), n)


def difference(a: Sequence[float], b: Sequence[float]) -> Interval:
    """Mean difference ``a - b`` of two independent samples with a Welch 95% interval."""
    ia, ib = interval(a), interval(b)
    if ia.n < 2 or ib.n < 2:
        return Interval(ia.mean - ib.mean, float("nan"), min(ia.n, ib.n))
    va = (ia.half / t975(ia.n - 1)) ** 2
    vb = (ib.half / t975(ib.n - 1)) ** 2
    se = math.sqrt(va + vb)
    if se == 0.0:
        return Interval(ia.mean - ib.mean, 0.0, min(ia.n, ib.n))
    df = (va + vb) ** 2 / (va ** 2 / (ia.n - 1) + vb ** 2 / (ib.n - 1))
    return Interval(ia.mean - ib.mean, t975(max(1, int(df))) * se, min(ia.n, ib.n))
