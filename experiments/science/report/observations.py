"""The paper's observations as tests that can fail, each against negative controls.

Every test turns one observation into a number per seed (a :class:`SeedRun` is one
configuration run with one seed) and judges the claim that its mean lies on one side of a
bound (:func:`dfrl.experiments.science.statistics.judge`), with Holm's correction over every
real row of the report (:func:`.standing.with_holm`). The same test is applied to the
negative controls, runs that cannot have learned, through the same pipeline (same seeds,
arenas, evaluation code) as the real runs (:class:`Controls`):

* the **zero table**: never trained; its greedy policy (ties broken at random, as the
  learners break them) evaluated like every real table;
* the **shuffled-reward** runs: federated Q-learning/average and standalone Q-learning in
  every arena, trained with ``reward_shuffle`` (:mod:`dfrl.robots.reward_shuffle`: the reward
  no longer depends on the state and action), the same iterations.

The run with a random behaviour policy (epsilon 1) is not a control: Q-learning is off-policy,
so its greedy table converges towards the same Q*; it is the **off-policy reference** of
test 1e. :meth:`.standing.Test.standing` says whether a test can tell learning from not
learning (not when a control's result is fixed by construction, a control passes, or shows
the same effect; cannot judge with no control or fewer than :data:`MIN_SEEDS` seeds).

Learning is read from behaviour, not from the sum of Q-values (which rises whatever the
robot does): the online reward per step (first quarter of the run vs last quarter), the time
that reward takes to make 90% of its gain, and the greedy policy's score in evaluations
(:mod:`dfrl.experiments.science.studies.history`).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from dfrl.experiments.science.curves import dip, late_growth
from dfrl.experiments.science.report.measures import (MIN_GAIN, SeedRun, arena_stat, final_score,
                                                      gain, greedy_gain, last_change, mean_q,
                                                      rate, robots_mean, t_reward90)
from dfrl.experiments.science.report.standing import (MIN_SEEDS, Standing, Test,  # noqa: F401
                                                      Verdict, above, below, by_seed,
                                                      control_difference, iv, with_holm)

#: Saturation: Q-sum growth in the last quarter under this share of its total growth.
SATURATED_GROWTH: float = 0.05

ZERO = "zero table"
SHUFFLED = "shuffled rewards"
REFERENCE = "off-policy reference (epsilon 1)"


@dataclass
class Controls:
    """The negative controls and the off-policy reference, one SeedRun per seed (the real
    runs' seeds, in the same order); an empty list when not run.

    ``zero``: evaluations only (no curves), one row per arena the real runs learn in (robot =
    arena) and its held-out arenas. ``shuffled_sa`` and ``reference_sa``: one SeedRun per seed
    holding every arena's standalone robot (the reference: R1 and R4)."""

    zero: list[SeedRun] = field(default_factory=list)
    shuffled_fed: list[SeedRun] = field(default_factory=list)
    shuffled_sa: list[SeedRun] = field(default_factory=list)
    reference_fed: list[SeedRun] = field(default_factory=list)
    reference_sa: list[SeedRun] = field(default_factory=list)


def _shuffled(fn: Callable[[list[SeedRun]], list[float]], c: Controls, side: str,
              bound: float = 0.0, fed_only: bool = False) -> list[Verdict]:
    claim = above if side == "above" else below
    out = [claim(f"{SHUFFLED} federated", fn(c.shuffled_fed), bound, kind="federated")]
    if not fed_only:
        out.append(claim(f"{SHUFFLED} standalone", fn(c.shuffled_sa), bound, kind="standalone"))
    return [v for v in out if v.values] if (c.shuffled_fed or c.shuffled_sa) else []


def paper_tests(fed: dict[str, list[SeedRun]], standalone: dict[str, list[SeedRun]],
                controls: Controls | None = None) -> list[Test]:
    """Every observation's test against the controls that apply to it.

    Parameters
    ----------
    fed : dict
        ``"qlearning/average"`` ... -> one :class:`SeedRun` per seed (seeds in the same order
        everywhere).
    standalone : dict
        ``"qlearning"``, ``"sarsa"`` -> per seed, one SeedRun holding every arena's robot.
    controls : Controls, optional
        None or empty lists: every test says it cannot judge.
    """
    c = controls or Controls()
    tests: list[Test] = []
    cum = lambda r: r["cumulative_reward"]  # noqa: E731
    # 1a: the paper's curve: the sum of Q-values rises (the zero table's is 0 by construction)
    final_q = lambda runs: [float(mean_q(r)[-1]) for r in runs]  # noqa: E731
    tests.append(Test(
        "1a", "The sum of Q-values rises (the paper's curve shape)",
        "robots' mean final sum of Q-values per seed; passes when its interval is above 0",
        [above(k, final_q(runs)) for k, runs in fed.items()],
        _shuffled(final_q, c, "above", fed_only=True),
        why_passes="the sum of Q-values rises whatever the rewards are paired with "
                   "(positive rewards, zero start)"))
    # 1b: behaviour improves
    g = lambda runs: [robots_mean(r, lambda x: gain(cum(x))) for r in runs]  # noqa: E731
    tests.append(Test(
        "1b", "The reward the robots earn rises as they learn",
        "reward per step in the last quarter minus the first quarter (robots' mean per seed); "
        "passes when the interval is above 0",
        [above(k, g(runs), kind="federated") for k, runs in fed.items()]
        + [above(k, g(runs), kind="standalone") for k, runs in standalone.items()],
        _shuffled(g, c, "above"),
        why_passes="exploration decays whatever the table holds, and the greedy action of a "
                   "table learnt from shuffled rewards earns more than random actions"))
    # 1c: the greedy policy drives without colliding
    gg = lambda runs: [greedy_gain(r) for r in runs]  # noqa: E731
    tests.append(Test(
        "1c", "The learnt greedy policy drives ahead without colliding",
        "greedy score (progress - 0.05 x collisions/1000) at the end, own and held-out arenas, "
        "minus the zero table's score with the report's fixed evaluation seed; passes when the "
        "interval is above 0.1. Controls: the zero table evaluated with each seed's evaluation "
        "seed, the shuffled-reward runs",
        [above(k, gg(runs), 0.1, kind="federated") for k, runs in fed.items()]
        + [above(k, gg(runs), 0.1, kind="standalone") for k, runs in standalone.items()],
        ([above(ZERO, gg(c.zero), 0.1)] if c.zero else []) + _shuffled(gg, c, "above", 0.1),
        why_passes="a table learnt from shuffled rewards can settle on driving ahead: its "
                   "most visited action grows largest"))
    # 1e: against the off-policy reference (a comparison, with the controls as checks)
    if c.reference_fed:
        minus = lambda runs, ref: by_seed(  # noqa: E731
            runs, ref, lambda a, b: final_score(a, robots=list(b.arenas)) - final_score(b))
        ctrl = ([above(f"{ZERO} minus the federated reference", minus(c.zero, c.reference_fed))]
                if c.zero else [])
        ctrl += [above(f"{SHUFFLED} federated minus the reference",
                       minus(c.shuffled_fed, c.reference_fed), kind="federated")]
        if c.shuffled_sa and c.reference_sa:
            ctrl.append(above(f"{SHUFFLED} standalone minus the reference",
                              minus(c.shuffled_sa, c.reference_sa), kind="standalone"))
        tests.append(Test(
            "1e", "The learnt greedy policy beats the off-policy reference",
            "final greedy score (own and held-out arenas) minus that of the same seed's "
            "off-policy reference (Q-learning from random behaviour, epsilon 1: the greedy "
            "table it converges towards), federated against the federated reference, "
            "standalone against the standalone one (R1 and R4); passes above 0",
            [above(k, minus(runs, c.reference_fed), kind="federated") for k, runs in fed.items()]
            + [above(k, minus(runs, c.reference_sa), kind="standalone")
               for k, runs in standalone.items() if c.reference_sa],
            ctrl))
    # 1d: saturation
    sat = lambda runs: [late_growth(mean_q(r)) for r in runs]  # noqa: E731
    tests.append(Test(
        "1d", "Learning saturates within the budget",
        f"share of the sum of Q-values' growth made in the last quarter (passes below "
        f"{SATURATED_GROWTH:.0%}); the greedy score's change over the last evaluation interval "
        f"is in the note",
        [below(k, sat(runs), SATURATED_GROWTH,
               note=f"last change of greedy score {iv([last_change(r) for r in runs])}")
         for k, runs in fed.items()],
        _shuffled(sat, c, "below", SATURATED_GROWTH, fed_only=True)))
    # 2: max dips more than average (no control: a shuffled max run is not made)
    real2 = []
    for algo in ("qlearning", "sarsa"):
        mx, av = fed.get(f"{algo}/max"), fed.get(f"{algo}/average")
        if mx and av:
            real2.append(above(algo, by_seed(mx, av, lambda a, b: dip(mean_q(a))[0]
                                              - dip(mean_q(b))[0]),
                               note="max dips " + str(iv([dip(mean_q(r))[0] for r in mx]))))
    tests.append(Test(
        "2", "Max aggregation shows a dip of the sum of Q-values before saturating",
        "largest drop of the robots' mean sum of Q-values below its running peak, max run minus "
        "average run of the same seed; passes when the interval is above 0",
        real2, []))
    # 3: R4 differs
    def r4_minus_others(r: SeedRun, fn: Callable[[np.ndarray], float]) -> float:
        others = [a for a in r.arenas.values() if a != "r4"]
        return arena_stat(r, "r4", fn) - robots_mean(r, fn, others)
    low = lambda runs: [r4_minus_others(r, lambda x: rate(cum(x), 0.0, 1.0))  # noqa: E731
                        for r in runs]
    tests.append(Test(
        "3a", "R4 earns the lowest reward (the paper's reading)",
        "R4's reward per step over the run minus the other arenas' mean; passes below 0",
        [below(k, low(runs)) for k, runs in fed.items()],
        _shuffled(low, c, "below", fed_only=True),
        why_passes="R4 is the most cluttered arena, so a robot that does not learn earns less "
                   "there too; 3b replaces this test"))
    g4 = lambda runs: [r4_minus_others(r, lambda x: gain(cum(x))) for r in runs]  # noqa: E731
    tests.append(Test(
        "3b", "R4 gains less from learning than the other arenas",
        "R4's reward gain (last quarter minus first) minus the other arenas' mean; passes below 0",
        [below(k, g4(runs)) for k, runs in fed.items()],
        _shuffled(g4, c, "below", fed_only=True)))
    # 4: R1 learns faster than R4 (standalone)
    t90 = lambda x: float(t_reward90(x["iteration"], cum(x)))  # noqa: E731
    r1_r4 = lambda runs: [arena_stat(r, "r4", t90) - arena_stat(r, "r1", t90)  # noqa: E731
                          for r in runs]
    clipped = (f"t_reward90 is the budget whenever the reward per step gains less than "
               f"{MIN_GAIN}")
    tests.append(Test(
        "4", "R1 learns faster than R4 (standalone)",
        "iterations for the reward per step to make 90% of its gain, R4 minus R1, per seed; "
        "passes above 0",
        [above(k, r1_r4(runs)) for k, runs in standalone.items()],
        [above(f"{SHUFFLED} standalone", r1_r4(c.shuffled_sa))] if c.shuffled_sa else [],
        why_fixed=clipped))
    # 5 and 6: federated against standalone
    def fed_minus_sa(f: SeedRun, s: SeedRun) -> float:
        arenas = sorted(set(f.arenas.values()) & set(s.arenas.values()))
        return robots_mean(f, t90, arenas) - robots_mean(s, t90, arenas)
    held = lambda f, s: final_score(f, "held_out") - final_score(s, "held_out")  # noqa: E731
    def pair_ctrl(fn: Callable[[SeedRun, SeedRun], float]) -> list[Verdict]:
        if not (c.shuffled_fed and c.shuffled_sa):
            return []
        return [above(SHUFFLED, by_seed(c.shuffled_fed, c.shuffled_sa, fn))]
    tests.append(Test(
        "5", "Standalone learning saturates faster than federated",
        "iterations for the reward per step to make 90% of its gain, federated minus standalone "
        "(same arenas and seed); passes above 0",
        [above(k, by_seed(runs, standalone[k.split("/")[0]], fed_minus_sa))
         for k, runs in fed.items()],
        pair_ctrl(fed_minus_sa), why_fixed=clipped + ", so federated minus standalone is 0"))
    tests.append(Test(
        "6", "The federated table does better on unseen arenas than a standalone one",
        "final greedy score in the held-out arenas, federated minus standalone (mean over the "
        "standalone arenas), same seed; passes above 0. The zero table is no control here: "
        "federated and standalone zero tables are the same table, 0 by construction",
        [above(k, by_seed(runs, standalone[k.split("/")[0]], held)) for k, runs in fed.items()],
        pair_ctrl(held)))
    return with_holm(tests)
