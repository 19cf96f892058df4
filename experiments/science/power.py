"""How many seeds an effect needs: the other side of the smallest detectable effect D that
every verdict "not significant at n = K (smallest detectable effect D)" prints.

D is the true distance from the null that a two-sided 5% test at n values finds with 80%
power. For a t interval (one sample, or paired differences: one value per seed) D =
(t(0.975, n - 1) + t(0.8, n - 1)) x sd / sqrt(n) (:meth:`~.statistics.Interval.detectable`);
:func:`seeds_needed` inverts it for a spread ``sd`` measured once. For a bootstrap interval
(a censored difference, a ratio of medians) D comes from the interval's width with normal
quantiles; its standard error falls like 1 / sqrt(n), so :func:`seeds_for` scales a D
measured at n seeds to the n at which it would reach a given effect (a difference: D
itself scales; a ratio: its logarithm does). Both are planning figures: the spread at the
new n is assumed to be the measured one.
"""

from __future__ import annotations

import math

from dfrl.experiments.science.statistics import POWER, t975, t_quantile

#: The largest n the functions search or return.
MOST = 100_000


def detectable_at(sd: float, n: int, power: float = POWER) -> float:
    """D of a one-sample or paired t test at ``n`` values of standard deviation ``sd``:
    ``(t(0.975, n - 1) + t(power, n - 1)) x sd / sqrt(n)``.

    Raises
    ------
    ValueError
        ``n`` < 2 or ``sd`` negative or not finite.
    """
    if n < 2:
        raise ValueError(f"a t test needs n >= 2, got {n}")
    if not (math.isfinite(sd) and sd >= 0):
        raise ValueError(f"sd must be finite and >= 0, got {sd}")
    return (t975(n - 1) + t_quantile(power, n - 1)) * sd / math.sqrt(n)


def seeds_needed(sd: float, effect: float, power: float = POWER) -> int:
    """The fewest values n (seeds; pairs of seeds for a paired test) at which a 5% t test
    of spread ``sd`` finds a true effect of size ``effect`` with probability ``power``: the
    smallest n >= 2 with :func:`detectable_at` (sd, n) <= |effect|.

    Raises
    ------
    ValueError
        ``effect`` is 0 or not finite, or more than :data:`MOST` values would be needed.
    """
    if not (math.isfinite(effect) and effect != 0):
        raise ValueError(f"effect must be finite and not 0, got {effect}")
    lo, hi = 2, 2
    while detectable_at(sd, hi, power) > abs(effect):
        if hi >= MOST:
            raise ValueError(f"more than {MOST} values for an effect of {effect} at sd {sd}")
        lo, hi = hi, min(2 * hi, MOST)
    while lo < hi:  # D falls with n: the first n that reaches the effect
        mid = (lo + hi) // 2
        if detectable_at(sd, mid, power) <= abs(effect):
            hi = mid
        else:
            lo = mid + 1
    return hi


def seeds_for(n: int, detectable: float, effect: float, scale: str = "difference") -> int:
    """The n at which a D measured at ``n`` values would reach ``effect``, its standard
    error falling like 1 / sqrt(n): ``ceil(n x (D / effect)^2)`` for a difference (scale
    ``"difference"``), ``ceil(n x (log D / log effect)^2)`` for a ratio (``"ratio"``, D and
    effect factors above 1); at least 2 (fewer than ``n`` when D is already below the
    effect).

    Raises
    ------
    ValueError
        A D that is not finite (an open interval: no n is known to suffice), an effect of 0
        (a ratio: <= 1), or an unknown scale.
    """
    if not math.isfinite(detectable):
        raise ValueError("the interval is open (D infinite): more seeds alone may not close it")
    if scale == "difference":
        if effect == 0:
            raise ValueError("effect must not be 0")
        factor = (abs(detectable) / abs(effect)) ** 2
    elif scale == "ratio":
        if not (effect > 1 and detectable > 1):
            raise ValueError(
                f"a ratio's D and effect are factors above 1, got {detectable}, {effect}"
            )
        factor = (math.log(detectable) / math.log(effect)) ** 2
    else:
        raise ValueError(f"scale is 'difference' or 'ratio', got {scale!r}")
    return max(2, math.ceil(n * factor - 1e-9))
