"""The transfer study's threshold of each unseen arena: the greedy score a learning phase
must reach there (``dfrl transfer-study``).

One threshold for every arena is too coarse: a score that a robot from any trained table
holds from the start in one arena (h1: open, thin pillars) may be beyond what a robot learns
in another (h2: a loop corridor) within the learning phase. So, unless given, an arena's
threshold is derived from that arena alone, with runs of their own that take no part in the
comparison:

* **reference runs**: ``runs`` robots learn the arena from zeros (Q-learning, the default
  configuration) for ``iterations`` steps, robot k with the training seed 70,000 + k;
* each run's **level** is the mean of its greedy score (the study's evaluation:
  ``eval_steps`` steps in episodes of ``episode_steps``, evaluation seed 75,000 + k) at the
  five points N/2, 5N/8, 3N/4, 7N/8 and N (N = ``iterations``): the score jumps between
  evaluations, its mean over the second half of the run is what the robot learnt;
* the arena's **reference level** is the mean of the runs' levels, and its **threshold**
  ``fraction`` x the reference level (default 0.75: three quarters of what a robot that
  learnt the arena itself for N steps holds).

Thresholds given explicitly (``--threshold X`` for every arena, ``--threshold h1=X``) are
used as they are. The seeds are apart from the sources' (1,000 s + k) and the learning
phases' (1,000,000 + 1,000 s + t, their evaluations + 500), so no source or phase shares a
stream with a reference run.

**No source starts at the threshold** (:func:`lift`): a threshold at or below a learning
phase's score at iteration 0 gives that phase a time of 0 whatever it then learns (a floor:
with 0.5 in h1, 7-10 of 20 phases were there from the start). So once every phase has run,
an arena's threshold (derived or given) is lifted to just above the best iteration-0 score of
any phase in that arena, of any source: no phase reaches it before it has learnt something.
:func:`time_to_threshold` reads a phase's time off its score curve.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from dfrl.experiments.science.studies.history import eval_job
from dfrl.experiments.science.studies.simulators import BATCHED, PYBULLET
from dfrl.robots.training import Trainer, TrainerConfig

#: Training seed of reference run k: REFERENCE_SEED_BASE + k; its evaluations: + 5,000.
REFERENCE_SEED_BASE = 70_000
REFERENCE_EVAL_OFFSET = 5_000
#: The points of a reference run, as fractions of its steps, whose mean score is its level.
LEVEL_POINTS = (4, 5, 6, 7, 8)  # eighths: N/2 .. N


@dataclass(frozen=True)
class Threshold:
    """The threshold of one unseen arena and where it comes from.

    Attributes
    ----------
    arena : str
    value : float
        The greedy score a learning phase in ``arena`` must reach: ``base``, or just above
        ``best_start`` when that is higher (:func:`lift`).
    given : bool
        Set on the command line (then ``levels`` is empty).
    fraction : float
        ``base`` / reference level (derived thresholds).
    levels : tuple of float
        Each reference run's level (mean score over the points ``LEVEL_POINTS``).
    iterations : int
        Steps of each reference run.
    base : float
        The threshold as given or derived, before :func:`lift` (NaN: the same as ``value``).
    best_start : float
        The best iteration-0 score of the learning phases in ``arena`` (NaN before
        :func:`lift`).
    phases : int
        The learning phases ``best_start`` is the best of.
    """

    arena: str
    value: float
    given: bool
    fraction: float = float("nan")
    levels: tuple[float, ...] = ()
    iterations: int = 0
    base: float = float("nan")
    best_start: float = float("nan")
    phases: int = 0

    def __post_init__(self) -> None:
        if math.isnan(self.base):
            object.__setattr__(self, "base", float(self.value))

    @property
    def level(self) -> float:
        """The reference level: the mean of the runs' levels (NaN when given)."""
        return float(np.mean(self.levels)) if self.levels else float("nan")

    @property
    def lifted(self) -> bool:
        """Raised above ``base`` by :func:`lift` (a phase started at or above ``base``)."""
        return self.value > self.base

    def origin(self) -> str:
        """How it was chosen, in words (the report's and the rows' ``threshold_from``)."""
        if self.given:
            said = f"given {self.base:.3g}"
        else:
            spread = ", ".join(f"{x:.3g}" for x in self.levels)
            said = (
                f"{self.fraction:g} x {self.level:.3g} = {self.base:.3g} (the mean level "
                f"of {len(self.levels)} reference runs of {self.iterations} steps from "
                f"zeros in {self.arena}: {spread})"
            )
        if self.lifted:
            said += (
                f"; lifted to just above {self.best_start:.4g}, the best iteration-0 "
                f"score of the {self.phases} learning phases"
            )
        elif self.phases:
            said += (
                f"; above every iteration-0 score of the {self.phases} learning phases "
                f"(best {self.best_start:.3g})"
            )
        return said

    def to_dict(self) -> dict[str, Any]:
        return {
            "arena": self.arena,
            "value": self.value,
            "given": self.given,
            "fraction": None if self.given else self.fraction,
            "levels": list(self.levels),
            "iterations": self.iterations,
            "base": self.base,
            "lifted": self.lifted,
            "best_start": None if math.isnan(self.best_start) else self.best_start,
            "phases": self.phases,
            "from": self.origin(),
        }


def lift(threshold: Threshold, starts: Sequence[float]) -> Threshold:
    """``threshold`` lifted, if need be, to just above the best of ``starts`` (the iteration-0
    scores of the learning phases in its arena, of every source): the smallest float above it
    (``numpy.nextafter``), so a phase must score higher than any phase started to reach it.
    A threshold already above every start is kept as it is.

    Raises
    ------
    ValueError
        No start, or one that is not finite.
    """
    if len(starts) == 0 or not all(np.isfinite(starts)):
        raise ValueError(
            f"{threshold.arena}: the iteration-0 scores must be finite and at "
            f"least one, got {list(starts)}"
        )
    best = float(max(starts))
    value = max(threshold.base, float(np.nextafter(best, math.inf)))
    return replace(threshold, value=value, best_start=best, phases=len(starts))


def time_to_threshold(
    scores: Sequence[tuple[int, float]], threshold: float, confirm: int, budget: int
) -> tuple[float, bool]:
    """A learning phase's time to ``threshold`` and whether it reached it: the grid point of
    the first of ``confirm`` evaluations in a row at or above it (``scores``: (iteration,
    greedy score) on the phase's grid, in order); ``(budget, False)``, censored, when no
    ``confirm`` evaluations in a row are.

    Raises
    ------
    ValueError
        ``confirm`` < 1.
    """
    if confirm < 1:
        raise ValueError(f"confirm must be >= 1, got {confirm}")
    run = 0
    for k, (_, score) in enumerate(scores):
        run = run + 1 if score >= threshold else 0
        if run == confirm:
            return float(scores[k - confirm + 1][0]), True
    return float(budget), False


def threshold_from(
    arena: str, levels: Sequence[float], fraction: float, iterations: int
) -> Threshold:
    """The derived threshold: ``fraction`` x the mean of ``levels``.

    Raises
    ------
    ValueError
        No level, a level that is not finite, or ``fraction`` outside (0, 1].
    """
    if not levels or not all(np.isfinite(levels)):
        raise ValueError(
            f"{arena}: reference levels must be finite and at least one, got {list(levels)}"
        )
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"threshold fraction must be in (0, 1], got {fraction}")
    level = float(np.mean(levels))
    return Threshold(
        arena, fraction * level, False, fraction, tuple(float(x) for x in levels), iterations
    )


def level_points(iterations: int) -> list[int]:
    """The steps of a reference run at which its score is taken: N/2, 5N/8, ..., N."""
    return sorted({max(1, iterations * k // 8) for k in LEVEL_POINTS})


def reference_job(
    arena: str, k: int, iterations: int, eval_steps: int, episode_steps: int
) -> float:
    """One reference run's level (a worker job): a robot learns ``arena`` from zeros for
    ``iterations`` steps; the mean of its greedy score at :func:`level_points`."""
    points = level_points(iterations)
    scores = []
    with Trainer(
        TrainerConfig(arena=arena, seed=REFERENCE_SEED_BASE + k, iterations=iterations)
    ) as t:
        for point in points:
            while t.iteration < point:
                t.step()
            ev = eval_job(
                TrainerConfig().to_dict(),
                t.q_table.copy(),
                arena,
                eval_steps,
                episode_steps,
                REFERENCE_SEED_BASE + REFERENCE_EVAL_OFFSET + k,
            )
            scores.append(float(ev["score"]))
    return float(np.mean(scores))


def thresholds_for(
    targets: Sequence[str],
    given: dict[str, float],
    fraction: float,
    iterations: int,
    runs: int,
    eval_steps: int,
    episode_steps: int,
    pool: Executor | None,
    sim: str = PYBULLET,
) -> dict[str, Threshold]:
    """Every target arena's threshold: ``given[arena]`` when set, else derived from
    ``runs`` reference runs of ``iterations`` steps, run on ``pool`` (pybullet) or in one
    batch (``sim`` batched: :func:`.batched.reference_levels`; ``pool`` unused)."""
    out = {a: Threshold(a, float(given[a]), True) for a in targets if a in given}
    todo = [a for a in targets if a not in given]
    jobs = [(a, k) for a in todo for k in range(1, runs + 1)]
    if sim == BATCHED:
        from dfrl.experiments.science.transfer.batched import reference_levels

        levels = reference_levels(jobs, iterations, eval_steps, episode_steps)
    else:
        if pool is None:
            raise ValueError("pybullet reference runs need a process pool")
        levels = list(
            pool.map(
                reference_job,
                [a for a, _ in jobs],
                [k for _, k in jobs],
                [iterations] * len(jobs),
                [eval_steps] * len(jobs),
                [episode_steps] * len(jobs),
            )
        )
    for a in todo:
        mine = [lv for (arena, _), lv in zip(jobs, levels) if arena == a]
        out[a] = threshold_from(a, mine, fraction, iterations)
    return {a: out[a] for a in targets}
