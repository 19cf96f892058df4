"""The per-seed measures of the paper's observations: what one configuration run with one
seed (:class:`SeedRun`) yields as one number (reward per step, its gain, the time to 90% of
it, greedy scores); :mod:`.observations` turns them into tests.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dfrl.experiments.science.curves import smooth

#: A reward gain per step below this is "no learning" (the saturation time is then the budget).
MIN_GAIN: float = 0.05
#: Window (iterations) of the smoothed reward per step.
RATE_WINDOW: int = 1000


@dataclass
class SeedRun:
    """One configuration, one seed: curves per robot, arenas, greedy evaluations."""

    curves: dict[str, np.ndarray]          # robot -> iteration, q_sum, cumulative_reward, ...
    arenas: dict[str, str]
    evals: list[dict[str, Any]] = field(default_factory=list)
    zero_score: dict[str, float] = field(default_factory=dict)   # arena -> zero table's score


# -- per-seed statistics ---------------------------------------------------------------------
def rate(cum: np.ndarray, a: float, b: float) -> float:
    """Mean reward per step over the fraction ``[a, b)`` of a cumulative-reward curve."""
    n = len(cum)
    i, j = int(a * n), max(int(b * n), int(a * n) + 1)
    before = cum[i - 1] if i > 0 else 0.0
    return float((cum[j - 1] - before) / (j - i))


def gain(cum: np.ndarray) -> float:
    """Reward per step in the last quarter minus in the first quarter."""
    return rate(cum, 0.75, 1.0) - rate(cum, 0.0, 0.25)


def t_reward90(it: np.ndarray, cum: np.ndarray) -> int:
    """First iteration at which the smoothed reward per step has made 90% of its gain from
    the first window to the last quarter; the last iteration when there is no gain."""
    r = np.diff(np.concatenate([[0.0], cum]))
    s = smooth(r, RATE_WINDOW)
    w = min(RATE_WINDOW, len(s)) - 1
    start, end = s[w], rate(cum, 0.75, 1.0)
    if end - start < MIN_GAIN:
        return int(it[-1])
    hit = np.nonzero(s[w:] >= start + 0.9 * (end - start))[0]
    return int(it[w + hit[0]]) if len(hit) else int(it[-1])


def robots_mean(run: SeedRun, fn: Callable[[np.ndarray], float],
                arenas: Sequence[str] | None = None) -> float:
    vals = [fn(c) for r, c in run.curves.items()
            if len(c) and (arenas is None or run.arenas.get(r) in arenas)]
    return float(np.mean(vals)) if vals else float("nan")


def mean_q(run: SeedRun) -> np.ndarray:
    n = min(len(c) for c in run.curves.values())
    return np.mean([c["q_sum"][:n] for c in run.curves.values()], axis=0)


def scores(run: SeedRun, role: str | None = None,
           robots: Sequence[str] | None = None) -> dict[int, float]:
    by: dict[int, list[float]] = {}
    for r in run.evals:
        if (role is None or r["role"] == role) and (robots is None or r["robot"] in robots):
            by.setdefault(int(r["iteration"]), []).append(float(r["score"]))
    return {k: float(np.mean(v)) for k, v in sorted(by.items())}


def final_score(run: SeedRun, role: str | None = None,
                robots: Sequence[str] | None = None) -> float:
    s = scores(run, role, robots)
    return s[max(s)] if s else float("nan")


def greedy_gain(run: SeedRun) -> float:
    """Final greedy score minus the zero table's, averaged over the evaluated arenas."""
    last = max((int(r["iteration"]) for r in run.evals), default=None)
    if last is None:
        return float("nan")
    d = [float(r["score"]) - run.zero_score.get(r["arena"], 0.0)
         for r in run.evals if int(r["iteration"]) == last]
    return float(np.mean(d))


def last_change(run: SeedRun) -> float:
    """Greedy score at the last evaluation minus at the one before."""
    s = list(scores(run).values())
    return s[-1] - s[-2] if len(s) >= 2 else float("nan")


def arena_stat(run: SeedRun, arena: str, fn: Callable[[np.ndarray], float]) -> float:
    return robots_mean(run, fn, [arena])
