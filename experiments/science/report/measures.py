"""What one condition run with one seed (:class:`SeedRun`) holds, and the greedy scores the
report and its figures read from it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class SeedRun:
    """One condition, one seed: curves per robot, arenas, greedy evaluations."""

    curves: dict[str, np.ndarray]  # robot -> iteration, q_sum, cumulative_reward, ...
    arenas: dict[str, str]
    evals: list[dict[str, Any]] = field(default_factory=list)


def mean_q(run: SeedRun) -> np.ndarray:
    """The robots' mean sum of Q-values, iteration by iteration (to the shortest curve)."""
    n = min(len(c) for c in run.curves.values())
    return np.mean([c["q_sum"][:n] for c in run.curves.values()], axis=0)


def scores(
    run: SeedRun, role: str | None = None, robots: Sequence[str] | None = None
) -> dict[int, float]:
    """Iteration -> mean greedy score of the evaluations in ``role`` of ``robots``."""
    by: dict[int, list[float]] = {}
    for r in run.evals:
        if (role is None or r["role"] == role) and (robots is None or r["robot"] in robots):
            by.setdefault(int(r["iteration"]), []).append(float(r["score"]))
    return {k: float(np.mean(v)) for k, v in sorted(by.items())}


def final_score(
    run: SeedRun, role: str | None = None, robots: Sequence[str] | None = None
) -> float:
    """The mean greedy score at the last evaluated iteration (nan without evaluations)."""
    s = scores(run, role, robots)
    return s[max(s)] if s else float("nan")
