"""Verdicts and whether a test can tell learning from not learning (its standing).

A :class:`Verdict` is one claim on one set of runs (per-seed values, the judgement of their
95% interval: :func:`dfrl.experiments.science.statistics.judge`); a :class:`Test` holds the
real runs' verdicts and its negative controls' (runs that cannot have learned, through the same
pipeline: :mod:`.observations`). :meth:`Test.standing` says whether the test is a test of
learning: not when a control's result is fixed by construction (declared, or the same value in
every seed), when a control passes, or when a control shows the same effect as a real row that
holds (real minus control, paired by seed, not significant); it cannot judge with no control
or fewer than :data:`MIN_SEEDS` seeds in a row.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from enum import Enum
from typing import Any

from dfrl.experiments.science.statistics import (Interval, Judgement, adjust, interval, judge,
                                                 paired, welch)

#: Fewest seeds a verdict is given on; with fewer, the report cannot judge.
MIN_SEEDS: int = 3


@dataclass(frozen=True)
class Verdict:
    """One claim on one set of runs: the per-seed values and the judgement of their interval.

    ``kind`` (``federated``, ``standalone`` or empty for both) matches real rows with the
    control rows they are compared with."""

    subject: str
    judgement: Judgement
    values: tuple[float, ...] = ()
    note: str = ""
    kind: str = ""

    @property
    def measure(self) -> Interval:
        return self.judgement.measure

    @property
    def passed(self) -> bool:
        return self.judgement.holds


def iv(values: Sequence[float]) -> Interval:
    """The interval of the values that are not nan (n = 0 when none is)."""
    vals = [v for v in values if not math.isnan(v)]
    return interval(vals) if vals else Interval(float("nan"), float("nan"), 0)


def _verdict(subject: str, values: Sequence[float], bound: float, side: str, note: str,
             kind: str) -> Verdict:
    vals = tuple(float(v) for v in values if not math.isnan(v))
    return Verdict(subject, judge(iv(vals), bound, side, MIN_SEEDS), vals, note, kind)


def above(subject: str, values: Sequence[float], bound: float = 0.0, note: str = "",
          kind: str = "") -> Verdict:
    """The claim "the mean of ``values`` is above ``bound``" (holds when its 95% interval lies
    wholly above it, with at least :data:`MIN_SEEDS` values)."""
    return _verdict(subject, values, bound, "above", note, kind)


def below(subject: str, values: Sequence[float], bound: float = 0.0, note: str = "",
          kind: str = "") -> Verdict:
    """The claim "the mean of ``values`` is below ``bound``"."""
    return _verdict(subject, values, bound, "below", note, kind)


class Standing(Enum):
    """Whether a test can tell learning from not learning."""

    TEST = "a test of learning"
    NOT_A_TEST = "not a test"
    CANNOT_JUDGE = "cannot judge"


@dataclass(frozen=True)
class Test:
    """An observation as a test: real verdicts, the controls', and what it means.

    ``fixed`` names why a control's result is fixed by construction, when it is by design; a
    control whose value is the same in every seed is found from the data (``why_fixed`` then
    says why, where known); ``why_passes`` says why a control passes, where known."""

    key: str
    title: str
    how: str
    real: list[Verdict]
    control: list[Verdict]
    fixed: str = ""
    why_fixed: str = ""
    why_passes: str = ""

    @property
    def holds(self) -> bool:
        return bool(self.real) and all(v.passed for v in self.real)

    @property
    def control_passes(self) -> bool:
        return any(v.passed for v in self.control)

    @property
    def has_control(self) -> bool:
        return any(v.measure.n > 0 for v in self.control)

    def standing(self) -> tuple[Standing, str]:
        """Whether this is a test of learning, and why (or why not)."""
        if not self.has_control:
            return Standing.CANNOT_JUDGE, "no control run applies"
        fewest = min(v.measure.n for v in self.real + self.control)
        if fewest < MIN_SEEDS:
            return Standing.CANNOT_JUDGE, (f"{fewest} seed(s) in a row, fewer than "
                                           f"{MIN_SEEDS}")
        if self.fixed:
            return Standing.NOT_A_TEST, f"the control's result is fixed by construction ({self.fixed})"
        for v in self.control:
            if v.values and max(v.values) == min(v.values):
                why = self.why_fixed
                return Standing.NOT_A_TEST, (
                    f"the control's result is fixed by construction: {v.subject} is "
                    f"{v.values[0]:.3g} in every seed" + (f" ({why})" if why else ""))
        passing = [v.subject for v in self.control if v.passed]
        if passing:
            why = self.why_passes
            return Standing.NOT_A_TEST, (f"the control passes it too ({', '.join(passing)})"
                                         + (f": {why}" if why else ""))
        for v in self.real:
            if not v.passed:
                continue
            for c in self.control:
                if c.kind and v.kind and c.kind != v.kind:
                    continue
                d = judge(control_difference(v.values, c.values), 0.0, v.judgement.side,
                          MIN_SEEDS)
                if not d.holds:
                    return Standing.NOT_A_TEST, (
                        f"the control shows the same effect: {v.subject} minus {c.subject} "
                        f"is {d.measure}, {d.words()}")
        return Standing.TEST, "every control fails it and differs from every run that passes"

    @property
    def is_test(self) -> bool:
        """A test of learning: it has controls that can fail, and they fail it."""
        return self.standing()[0] is Standing.TEST


def control_difference(real: Sequence[float], control: Sequence[float]) -> Interval:
    """Real minus control: paired by seed when both have a value for every seed (the
    control runs with the same seeds, in the same order), otherwise Welch."""
    return paired(real, control) if len(real) == len(control) else welch(real, control)


def with_holm(tests: list[Test]) -> list[Test]:
    """The tests with Holm's correction applied over the family of every real row of every
    test (control rows are checks, not claims, and stay as they are)."""
    family = [v.judgement for t in tests for v in t.real]
    adjusted = iter(adjust(family))
    return [replace(t, real=[replace(v, judgement=next(adjusted)) for v in t.real])
            for t in tests]


def by_seed(a: Sequence[Any], b: Sequence[Any], fn: Callable[[Any, Any], float]) -> list[float]:
    """``fn`` of the runs of the same seed (both lists in the seeds' order)."""
    return [fn(x, y) for x, y in zip(a, b)]
