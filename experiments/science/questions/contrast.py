"""A contrast between two conditions paired by seed, its verdict, and the power it had.

One row of a question: the per-seed values of condition A and of condition B (the same seeds,
the same arenas and evaluation episodes), their differences ``A - B`` and the t interval of
their mean (:func:`scipy.stats.ttest_rel`); Holm's correction over the row's family
(:func:`statsmodels.stats.multitest.multipletests`); the smallest effect the row could detect
with 80% power and the seeds a stated effect needs
(:class:`statsmodels.stats.power.TTestPower`, a paired t test is a one-sample test of the
differences). The power is computed at the strictest level Holm's procedure can ask of a row,
5% / m for a family of m rows (Bonferroni's, which Holm's never asks more than), so a "not
significant at n = K (smallest detectable effect D)" is honest whatever the row's rank.

The words of a verdict (:class:`Outcome`):

* ``holds``: Holm-adjusted p < 5% and the estimate on the claimed side;
* ``refuted``: the 95% interval excludes every effect of at least delta on the claimed side
  (for a two-sided claim: the interval lies within (-delta, delta), the conditions do not
  differ by delta or more);
* ``not significant at n = K (smallest detectable effect D)``: neither;
* ``cannot judge``: fewer than :data:`MIN_SEEDS` pairs, a zero spread (every seed gives the
  same difference: nothing to estimate a variance from, the interval would have zero width),
  or a row whose control failed its check (the reason is given).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np

#: Fewest pairs of seeds a row is judged on.
MIN_SEEDS: int = 3
#: The test level and the power of the detectable effects.
ALPHA: float = 0.05
POWER: float = 0.8
#: The largest number of seeds the planning figures report (more is "more than" this).
MOST_SEEDS: int = 10_000


def need_statsmodels() -> None:
    """Raise a clear ImportError when the ``science`` extra is not installed."""
    try:
        import statsmodels  # noqa: F401
    except ImportError as exc:
        raise ImportError(
            "the questions need statsmodels: pip install 'dfrl[science]' "
            f"(or run scripts/setup.sh): {exc}"
        ) from exc


class Outcome(Enum):
    """What a row concludes."""

    HOLDS = "holds"
    REFUTED = "refuted"
    NOT_SIGNIFICANT = "not significant"
    CANNOT_JUDGE = "cannot judge"


@dataclass(frozen=True)
class Contrast:
    """``A - B`` paired by seed.

    Attributes
    ----------
    a, b : tuple of float
        Per-seed values of the two conditions, in the order of ``seeds``.
    side : str
        ``"above"`` (the claim: A exceeds B), ``"below"`` or ``"two-sided"`` (A differs from B).
    delta : float
        The smallest effect of interest (> 0, in the measure's unit).
    family_size : int
        Rows in the row's family (the power is computed at ALPHA / family_size).
    """

    seeds: tuple[int, ...]
    a: tuple[float, ...]
    b: tuple[float, ...]
    side: str
    delta: float
    family_size: int = 1

    def __post_init__(self) -> None:
        if not (len(self.seeds) == len(self.a) == len(self.b)):
            raise ValueError(
                f"a contrast needs one value per seed on each side: {len(self.seeds)}"
                f" seeds, {len(self.a)} and {len(self.b)} values"
            )
        if self.side not in ("above", "below", "two-sided"):
            raise ValueError(f"side: above, below or two-sided, got {self.side!r}")
        if not (math.isfinite(self.delta) and self.delta > 0):
            raise ValueError(f"delta must be a finite effect > 0, got {self.delta}")

    @property
    def differences(self) -> np.ndarray:
        return np.asarray(self.a, dtype=float) - np.asarray(self.b, dtype=float)

    @property
    def n(self) -> int:
        return len(self.seeds)

    @property
    def estimate(self) -> float:
        return float(np.mean(self.differences)) if self.n else float("nan")

    @property
    def sd(self) -> float:
        return float(np.std(self.differences, ddof=1)) if self.n >= 2 else float("nan")

    @property
    def degenerate(self) -> bool:
        """Too few pairs, a non-finite value, or a zero spread: no interval to judge by."""
        d = self.differences
        return self.n < 2 or not bool(np.isfinite(d).all()) or not self.sd > 0

    def interval(self, level: float = 1 - ALPHA) -> tuple[float, float]:
        """The ``level`` t interval of the mean difference ((nan, nan) when degenerate)."""
        if self.degenerate:
            return float("nan"), float("nan")
        from scipy import stats

        ci = stats.ttest_rel(self.a, self.b).confidence_interval(level)
        return float(ci.low), float(ci.high)

    @property
    def p(self) -> float:
        """Two-sided p of "the mean difference is 0" (one-sided on the claimed side for
        ``above``/``below``: the claim is directional)."""
        if self.degenerate:
            return float("nan")
        from scipy import stats

        alt = {"above": "greater", "below": "less", "two-sided": "two-sided"}[self.side]
        return float(stats.ttest_rel(self.a, self.b, alternative=alt).pvalue)

    def detectable(self) -> float:
        """The smallest true difference this row finds with :data:`POWER` at its n and
        spread, at level ALPHA / family_size (inf below 2 pairs)."""
        if self.n < 2 or not math.isfinite(self.sd):
            return float("inf")
        if self.sd == 0:
            return 0.0
        return self._effect_size(self.n) * self.sd

    def seeds_needed(self) -> int | None:
        """Pairs of seeds at which this row detects ``delta`` with :data:`POWER` (the spread
        measured here held fixed); None when the spread is unknown or it would need more than
        :data:`MOST_SEEDS`."""
        if self.n < 2 or not math.isfinite(self.sd) or self.sd == 0:
            return None
        import warnings

        from statsmodels.stats.power import TTestPower

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # a failed root find gives nan: handled
                guess = _scalar(
                    TTestPower().solve_power(
                        effect_size=self.delta / self.sd,
                        nobs=None,
                        power=POWER,
                        alpha=ALPHA / self.family_size,
                        alternative=self._alternative,
                    )
                )
        except (ValueError, ArithmeticError):
            return None
        if not math.isfinite(guess) or guess > MOST_SEEDS:
            return None
        n = max(2, math.ceil(guess))
        while n > 2 and self._effect_size(n - 1) * self.sd <= self.delta:
            n -= 1  # the root finder may overshoot by one
        while n <= MOST_SEEDS and self._effect_size(n) * self.sd > self.delta:
            n += 1
        return n if n <= MOST_SEEDS else None

    @property
    def _alternative(self) -> str:
        return "two-sided" if self.side == "two-sided" else "larger"

    def _effect_size(self, n: int) -> float:
        import warnings

        from statsmodels.stats.power import TTestPower

        alpha = ALPHA / self.family_size
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the root finder's failure is handled below
            d = _scalar(
                TTestPower().solve_power(
                    effect_size=None,
                    nobs=n,
                    power=POWER,
                    alpha=alpha,
                    alternative=self._alternative,
                )
            )
        if math.isfinite(d):
            return d
        # beyond the solver's bracket (tiny n at a strict level): the central-t approximation
        from scipy import stats

        tail = alpha / 2 if self.side == "two-sided" else alpha
        return float((stats.t.ppf(1 - tail, n - 1) + stats.t.ppf(POWER, n - 1)) / math.sqrt(n))


def _scalar(x: object) -> float:
    """statsmodels' solvers return a float or a one-element array."""
    return float(np.ravel(np.asarray(x, dtype=float))[0])


@dataclass(frozen=True)
class Judged:
    """A contrast with its verdict inside its family."""

    contrast: Contrast
    outcome: Outcome
    p_adjusted: float
    reason: str = ""

    def words(self) -> str:
        """The verdict as the report prints it."""
        c = self.contrast
        if self.outcome is Outcome.NOT_SIGNIFICANT:
            return f"not significant at n = {c.n} (smallest detectable effect {c.detectable():.3g})"
        if self.outcome is Outcome.CANNOT_JUDGE:
            return f"cannot judge ({self.reason})" if self.reason else "cannot judge"
        if self.outcome is Outcome.HOLDS and c.side == "two-sided":
            return "holds (A higher)" if c.estimate > 0 else "holds (B higher)"
        return self.outcome.value


def judge_family(
    contrasts: Sequence[Contrast], vetoes: Sequence[str] | None = None
) -> list[Judged]:
    """Every row of one family judged, with Holm's correction over the rows that can be judged.

    ``vetoes[i]``, when not empty, makes row i "cannot judge" with that reason (its control
    failed its check); such a row takes no part in the correction.
    """
    need_statsmodels()
    from statsmodels.stats.multitest import multipletests

    vetoes = list(vetoes) if vetoes is not None else [""] * len(contrasts)
    reasons = []
    for c, veto in zip(contrasts, vetoes):
        if veto:
            reasons.append(veto)
        elif c.n < MIN_SEEDS:
            reasons.append(f"n = {c.n} < {MIN_SEEDS} seeds")
        elif c.degenerate:
            reasons.append(
                "every seed gives the same difference: no spread to judge by"
                if np.isfinite(c.differences).all()
                else "a value is not finite"
            )
        else:
            reasons.append("")
    live = [i for i, r in enumerate(reasons) if not r]
    adjusted = [float("nan")] * len(contrasts)
    if live:
        padj = multipletests([contrasts[i].p for i in live], alpha=ALPHA, method="holm")[1]
        for i, p in zip(live, padj):
            adjusted[i] = float(p)
    out = []
    for i, c in enumerate(contrasts):
        c = replace(c, family_size=max(1, len(live)))
        if reasons[i]:
            out.append(Judged(c, Outcome.CANNOT_JUDGE, float("nan"), reasons[i]))
            continue
        out.append(Judged(c, _outcome(c, adjusted[i]), adjusted[i]))
    return out


def _outcome(c: Contrast, p_adjusted: float) -> Outcome:
    low, high = c.interval()
    if p_adjusted < ALPHA:
        return Outcome.HOLDS
    if c.side == "above" and high < c.delta:
        return Outcome.REFUTED
    if c.side == "below" and low > -c.delta:
        return Outcome.REFUTED
    if c.side == "two-sided" and -c.delta < low and high < c.delta:
        return Outcome.REFUTED
    return Outcome.NOT_SIGNIFICANT
