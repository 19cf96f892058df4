"""Statistics of learning curves that the paper's observations are checked against."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dfrl.experiments.driver.config import ExperimentConfig

COMBOS: tuple[tuple[str, str], ...] = (("qlearning", "average"), ("qlearning", "max"),
                                       ("sarsa", "average"), ("sarsa", "max"))
ALGO_NAMES = {"qlearning": "Q-learning", "sarsa": "SARSA"}


# -- curve statistics ------------------------------------------------------------------------
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
        out.append(RunStats(robot, arenas.get(robot, robot), float(cur["q_sum"][-1]),
                            float(cur["cumulative_reward"][-1]), int(cur["collisions"][-1]),
                            t_fraction(cur["iteration"], cur["q_sum"]), late_growth(cur["q_sum"]),
                            reward_rate(cur["cumulative_reward"], "first"),
                            reward_rate(cur["cumulative_reward"], "last"), d,
                            int(cur["iteration"][k])))
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
