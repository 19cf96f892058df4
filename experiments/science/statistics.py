"""The statistics that the reports and the studies share: learning-curve measures and means
with 95% Student-t confidence intervals (for results over a few seeds).

Pure functions of numbers and arrays; :mod:`.report` (the paper's observations and figures)
and :mod:`.studies` (sweep, speed-up, transfer) both use them, neither imports the other.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


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


# -- means and intervals over seeds ----------------------------------------------------------
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
