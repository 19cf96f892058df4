"""Per-robot statistics of runs that the paper's observations are checked against (the curve
measures themselves are :mod:`dfrl.experiments.science.statistics`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.science.curves import dip, late_growth, reward_rate, t_fraction

COMBOS: tuple[tuple[str, str], ...] = (
    ("qlearning", "average"),
    ("qlearning", "max"),
    ("sarsa", "average"),
    ("sarsa", "max"),
)
ALGO_NAMES = {"qlearning": "Q-learning", "sarsa": "SARSA"}


@dataclass
class RunStats:
    """Per-robot statistics of one run."""

    robot: str
    arena: str
    final_q: float
    final_reward: float
    collisions: int
    t90_q: int
    late_growth_q: float
    rate_first: float
    rate_last: float
    dip: float
    dip_at: int


def stats_of(curves: dict[str, np.ndarray], arenas: dict[str, str]) -> list[RunStats]:
    """Per-robot statistics of one run's curves (robot -> structured metrics array)."""
    out = []
    for robot, cur in curves.items():
        d, k = dip(cur["q_sum"])
        out.append(
            RunStats(
                robot,
                arenas.get(robot, robot),
                float(cur["q_sum"][-1]),
                float(cur["cumulative_reward"][-1]),
                int(cur["collisions"][-1]),
                t_fraction(cur["iteration"], cur["q_sum"]),
                late_growth(cur["q_sum"]),
                reward_rate(cur["cumulative_reward"], "first"),
                reward_rate(cur["cumulative_reward"], "last"),
                d,
                int(cur["iteration"][k]),
            )
        )
    return out


@dataclass
class CombinationRun:
    """One federated run of the reproduction (an algorithm with a method) and its figures."""

    cfg: ExperimentConfig
    curves: dict[str, np.ndarray]
    arenas: dict[str, str]
    wall: float
    ok: bool
    rounds: int
    equal: int
    stats: list[RunStats]


@dataclass
class StandaloneRuns:
    """The standalone runs of one algorithm, one per arena."""

    curves: dict[str, np.ndarray]
    stats: list[RunStats]
