"""The paper's observations as tests that can fail: per-seed statistics, 95% intervals, verdicts.

Every test turns one observation into a number per seed (a :class:`SeedRun` is one
configuration run with one seed) and judges the claim that its mean lies on one side of a
bound (:func:`dfrl.experiments.science.statistics.judge`: holds, refuted, not significant at
n = K with the smallest detectable effect, or cannot judge below :data:`MIN_SEEDS` seeds),
with Holm's correction over every real row of the report (:func:`with_holm`). The same test is
applied to the negative control (the same configuration with a random behaviour policy,
epsilon 1 throughout). :meth:`Test.standing` says whether the test can tell learning from not
learning: not when the control's result is fixed by construction (declared, or the same value
in every seed), passes, or shows the same effect as a real row that holds; and the report
cannot judge with no control or fewer than :data:`MIN_SEEDS` seeds.

Learning is read from behaviour, not from the sum of Q-values (which rises whatever the
robot does): the online reward per step (first quarter of the run vs last quarter), the time
that reward takes to make 90% of its gain, and the greedy policy's score in evaluations
(:mod:`dfrl.experiments.science.studies.history`).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np

from dfrl.experiments.science.report.measures import (MIN_GAIN, SeedRun, arena_stat, final_score,
                                                      gain, greedy_gain, last_change, mean_q,
                                                      rate, robots_mean, t_reward90)
from dfrl.experiments.science.curves import dip, late_growth
from dfrl.experiments.science.statistics import (Interval, Judgement, adjust, interval, judge,
                                                 paired, welch)

#: Saturation: Q-sum growth in the last quarter under this share of its total growth.
SATURATED_GROWTH: float = 0.05
#: Saturation: greedy score change between the last two evaluations within this.
STABLE_SCORE: float = 0.1


# -- verdicts --------------------------------------------------------------------------------
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


def _iv(values: Sequence[float]) -> Interval:
    vals = [v for v in values if not math.isnan(v)]
    return interval(vals) if vals else Interval(float("nan"), float("nan"), 0)


def _verdict(subject: str, values: Sequence[float], bound: float, side: str, note: str,
             kind: str) -> Verdict:
    vals = tuple(float(v) for v in values if not math.isnan(v))
    return Verdict(subject, judge(_iv(vals), bound, side, MIN_SEEDS), vals, note, kind)


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
    """An observation as a test: real verdicts, the control's, and what it means.

    ``fixed`` names why the control's result is fixed by construction, when it is by design
    (a control that is the reference itself); a control whose value is the same in every
    seed is found from the data."""

    key: str
    title: str
    how: str
    real: list[Verdict]
    control: list[Verdict]
    fixed: str = ""

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
                why = WHY_FIXED.get(self.key, "")
                return Standing.NOT_A_TEST, (
                    f"the control's result is fixed by construction: {v.subject} is "
                    f"{v.values[0]:.3g} in every seed" + (f" ({why})" if why else ""))
        if self.control_passes:
            why = WHY_CONTROL_PASSES.get(self.key, "")
            return Standing.NOT_A_TEST, "the control passes it too" + (f" ({why})" if why else "")
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
        return Standing.TEST, "the control fails it and differs from every run that passes"

    @property
    def is_test(self) -> bool:
        """A test of learning: it has a control that can fail, and it fails it."""
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


def by_seed(a: Sequence[SeedRun], b: Sequence[SeedRun],
            fn: Callable[[SeedRun, SeedRun], float]) -> list[float]:
    return [fn(x, y) for x, y in zip(a, b)]


def paper_tests(fed: dict[str, list[SeedRun]], standalone: dict[str, list[SeedRun]],
                control_fed: list[SeedRun], control_sa: list[SeedRun]) -> list[Test]:
    """Every observation's test.

    Parameters
    ----------
    fed : dict
        ``"qlearning/average"`` ... -> one :class:`SeedRun` per seed (seeds in the same order
        everywhere).
    standalone : dict
        ``"qlearning"``, ``"sarsa"`` -> per seed, one SeedRun holding every arena's robot.
    control_fed, control_sa : list of SeedRun
        The control: federated Q-learning/average and standalone Q-learning, epsilon 1.
    """
    tests: list[Test] = []
    cum = lambda c: c["cumulative_reward"]  # noqa: E731
    ctrl_name = "control (epsilon 1)"
    # 1a: the paper's curve: the sum of Q-values rises
    tests.append(Test(
        "1a", "The sum of Q-values rises (the paper's curve shape)",
        "robots' mean final sum of Q-values per seed; passes when its interval is above 0",
        [above(k, [float(mean_q(r)[-1]) for r in runs]) for k, runs in fed.items()],
        [above(ctrl_name, [float(mean_q(r)[-1]) for r in control_fed])]))
    # 1b: behaviour improves
    g = lambda r: robots_mean(r, lambda c: gain(cum(c)))  # noqa: E731
    tests.append(Test(
        "1b", "The reward the robots earn rises as they learn",
        "reward per step in the last quarter minus the first quarter (robots' mean per seed); "
        "passes when the interval is above 0",
        [above(k, [g(r) for r in runs], kind="federated") for k, runs in fed.items()]
        + [above(k, [g(r) for r in runs], kind="standalone") for k, runs in standalone.items()],
        [above(ctrl_name + " federated", [g(r) for r in control_fed], kind="federated"),
         above(ctrl_name + " standalone", [g(r) for r in control_sa], kind="standalone")]))
    # 1c: the greedy policy drives without colliding
    tests.append(Test(
        "1c", "The learnt greedy policy drives ahead without colliding",
        "greedy score (progress - 0.05 x collisions/1000) at the end, own and held-out arenas, "
        "minus the zero table's score (a random policy); passes when the interval is above 0.1",
        [above(k, [greedy_gain(r) for r in runs], 0.1, kind="federated")
         for k, runs in fed.items()]
        + [above(k, [greedy_gain(r) for r in runs], 0.1, kind="standalone")
           for k, runs in standalone.items()],
        [above(ctrl_name + " federated", [greedy_gain(r) for r in control_fed], 0.1,
               kind="federated"),
         above(ctrl_name + " standalone", [greedy_gain(r) for r in control_sa], 0.1,
               kind="standalone")]))
    # 1e: 1c fixed: off-policy Q-learning from random behaviour also learns a table whose
    # greedy policy drives (1c passes the control), so the reference is the control itself
    if control_fed:
        ref = lambda runs: by_seed(runs, control_fed,  # noqa: E731
                                   lambda a, b: final_score(a) - final_score(b))
        tests.append(Test(
            "1e", "The learnt greedy policy beats the greedy policy learnt from random behaviour",
            "final greedy score (own and held-out arenas) minus the control's of the same seed "
            "(federated control; standalone runs against the standalone control); passes "
            "above 0. 1c fixed, but the control is the reference, so its own row is 0 by "
            "definition and cannot fail",
            [above(k, ref(runs)) for k, runs in fed.items()]
            + [above(k, by_seed(runs, control_sa, lambda a, b: final_score(a, robots=list(
                b.curves)) - final_score(b))) for k, runs in standalone.items()],
            [below(ctrl_name, [0.0] * len(control_fed), note="the reference: 0 by construction")],
            fixed="the control is the reference: every row is a run minus the control, so the "
                  "control's own row is 0 by definition"))
    # 1d: saturation
    sat = lambda runs: [late_growth(mean_q(r)) for r in runs]  # noqa: E731
    tests.append(Test(
        "1d", "Learning saturates within the budget",
        f"share of the sum of Q-values' growth made in the last quarter (passes below "
        f"{SATURATED_GROWTH:.0%}); the greedy score's change over the last evaluation interval "
        f"is in the note",
        [below(k, sat(runs), SATURATED_GROWTH,
               note=f"last change of greedy score {_iv([last_change(r) for r in runs])}")
         for k, runs in fed.items()],
        [below(ctrl_name, sat(control_fed), SATURATED_GROWTH)]))
    # 2: max dips more than average
    real2 = []
    for algo in ("qlearning", "sarsa"):
        mx, av = fed.get(f"{algo}/max"), fed.get(f"{algo}/average")
        if mx and av:
            real2.append(above(algo, by_seed(mx, av, lambda a, b: dip(mean_q(a))[0] - dip(mean_q(b))[0]),
                               note="max dips " + str(_iv([dip(mean_q(r))[0] for r in mx]))))
    tests.append(Test(
        "2", "Max aggregation shows a dip of the sum of Q-values before saturating",
        "largest drop of the robots' mean sum of Q-values below its running peak, max run minus "
        "average run of the same seed; passes when the interval is above 0",
        real2, []))
    # 3: R4 differs
    def r4_minus_others(r: SeedRun, fn: Callable[[np.ndarray], float]) -> float:
        others = [a for a in r.arenas.values() if a != "r4"]
        return arena_stat(r, "r4", fn) - robots_mean(r, fn, others)
    low_reward = lambda c: rate(cum(c), 0.0, 1.0)  # noqa: E731
    tests.append(Test(
        "3a", "R4 earns the lowest reward (the paper's reading)",
        "R4's reward per step over the run minus the other arenas' mean; passes below 0",
        [below(k, [r4_minus_others(r, low_reward) for r in runs]) for k, runs in fed.items()],
        [below(ctrl_name, [r4_minus_others(r, low_reward) for r in control_fed])]))
    tests.append(Test(
        "3b", "R4 gains less from learning than the other arenas",
        "R4's reward gain (last quarter minus first) minus the other arenas' mean; passes below 0",
        [below(k, [r4_minus_others(r, lambda c: gain(cum(c))) for r in runs])
         for k, runs in fed.items()],
        [below(ctrl_name, [r4_minus_others(r, lambda c: gain(cum(c))) for r in control_fed])]))
    # 4: R1 learns faster than R4 (standalone)
    t90 = lambda c: float(t_reward90(c["iteration"], cum(c)))  # noqa: E731
    r1_r4 = lambda r: arena_stat(r, "r4", t90) - arena_stat(r, "r1", t90)  # noqa: E731
    tests.append(Test(
        "4", "R1 learns faster than R4 (standalone)",
        "iterations for the reward per step to make 90% of its gain, R4 minus R1, per seed; "
        "passes above 0",
        [above(k, [r1_r4(r) for r in runs]) for k, runs in standalone.items()],
        [above(ctrl_name, [r1_r4(r) for r in control_sa])]))
    # 5: standalone saturates faster than federated
    def fed_minus_sa(f: SeedRun, s: SeedRun) -> float:
        arenas = sorted(set(f.arenas.values()) & set(s.arenas.values()))
        return robots_mean(f, t90, arenas) - robots_mean(s, t90, arenas)
    tests.append(Test(
        "5", "Standalone learning saturates faster than federated",
        "iterations for the reward per step to make 90% of its gain, federated minus standalone "
        "(same arenas and seed); passes above 0",
        [above(k, by_seed(runs, standalone[k.split("/")[0]], fed_minus_sa))
         for k, runs in fed.items()],
        [above(ctrl_name, by_seed(control_fed, control_sa, fed_minus_sa))]))
    # 6: federation helps on unseen arenas
    held = lambda f, s: final_score(f, "held_out") - final_score(s, "held_out")  # noqa: E731
    tests.append(Test(
        "6", "The federated table does better on unseen arenas than a standalone one",
        "final greedy score in the held-out arenas, federated minus standalone (mean over the "
        "standalone arenas), same seed; passes above 0",
        [above(k, by_seed(runs, standalone[k.split("/")[0]], held)) for k, runs in fed.items()],
        [above(ctrl_name, by_seed(control_fed, control_sa, held))]))
    return with_holm(tests)


#: Why a control's value is the same in every seed, where we know.
WHY_FIXED = {
    "4": f"t_reward90 is the budget whenever the reward per step gains less than {MIN_GAIN}, "
         "as it does under random behaviour",
    "5": f"t_reward90 is the budget whenever the reward per step gains less than {MIN_GAIN}, "
         "as it does under random behaviour, so federated minus standalone is 0",
}

#: Why a test passes the control, where we know.
WHY_CONTROL_PASSES = {
    "1a": "the sum of Q-values rises whatever the robot does (positive rewards, zero start)",
    "1c": "Q-learning is off-policy: a table learnt from random behaviour has a greedy policy "
          "that drives too; 1e replaces this test",
    "3a": "R4 is the most cluttered arena, so a random robot earns less there too; 3b replaces "
          "this test",
}
