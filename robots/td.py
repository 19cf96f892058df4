"""Pure maths shared by every learner: TD targets, greedy and epsilon-greedy choices, schedules.

Tabular learners (:mod:`dfrl.robots.learners`) apply them to rows of their table, the
function-approximation learners (:mod:`dfrl.robots.linear`, :mod:`dfrl.robots.dqn`) to the
action values their model computes for an observation. :mod:`dfrl.robots.learners` re-exports
every name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np


def q_learning_target(reward: float, next_q_row: np.ndarray, gamma: float, terminal: bool) -> float:
    """Q-learning target ``r + gamma * max_a' Q(s', a')`` (``r`` when terminal).

    Parameters
    ----------
    reward : float
    next_q_row : np.ndarray, shape (n_actions,)
        ``Q(s', .)``.
    gamma : float
        Discount in ``[0, 1]``.
    terminal : bool
        No bootstrap after a terminal transition.
    """
    if terminal:
        return float(reward)
    return float(reward + gamma * max(next_q_row.tolist()))


def sarsa_target(reward: float, next_q: float, gamma: float, terminal: bool) -> float:
    """SARSA target ``r + gamma * Q(s', a')`` for the action ``a'`` actually chosen."""
    if terminal:
        return float(reward)
    return float(reward + gamma * next_q)


def td_update(q_sa: float, target: float, alpha: float) -> float:
    """Move ``q_sa`` towards ``target`` by a step ``alpha``: ``q + alpha * (target - q)``."""
    return float(q_sa + alpha * (target - q_sa))


def greedy_action(q_row: np.ndarray, rng: np.random.Generator | None = None) -> int:
    """An action of highest value; ties broken uniformly with ``rng`` (lowest index without).

    Parameters
    ----------
    q_row : np.ndarray, shape (n_actions,)
    rng : np.random.Generator, optional
    """
    row = q_row.tolist()  # plain floats: faster than numpy for a handful of actions
    top = max(row)
    best = [i for i, v in enumerate(row) if v == top]
    if rng is None or len(best) == 1:
        return best[0]
    return best[int(rng.integers(len(best)))]


def epsilon_greedy(q_row: np.ndarray, epsilon: float, rng: np.random.Generator) -> int:
    """With probability ``epsilon`` a uniform random action, else a greedy one.

    Parameters
    ----------
    q_row : np.ndarray, shape (n_actions,)
    epsilon : float
        Exploration probability in ``[0, 1]``.
    rng : np.random.Generator
    """
    if epsilon > 0.0 and rng.random() < epsilon:
        return int(rng.integers(q_row.shape[0]))
    return greedy_action(q_row, rng)


class ScheduleKind(str, Enum):
    """Shape of the exploration schedule."""

    CONSTANT = "constant"  #: epsilon = start
    LINEAR = "linear"  #: start -> end linearly over ``decay_steps``, then end
    EXPONENTIAL = "exponential"  #: end + (start - end) * exp(-t / decay_steps)


@dataclass(frozen=True)
class EpsilonSchedule:
    """Exploration probability as a function of the learner's update count ``t``."""

    kind: ScheduleKind = ScheduleKind.LINEAR
    start: float = 0.3
    end: float = 0.02
    decay_steps: int = 4000

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", ScheduleKind(self.kind))
        if not (0.0 <= self.end <= 1.0 and 0.0 <= self.start <= 1.0):
            raise ValueError("epsilon start and end must be in [0, 1]")
        if self.decay_steps <= 0:
            raise ValueError("decay_steps must be positive")

    def value(self, t: int) -> float:
        """Epsilon after ``t`` updates."""
        if self.kind is ScheduleKind.CONSTANT:
            return self.start
        if self.kind is ScheduleKind.LINEAR:
            frac = min(t / self.decay_steps, 1.0)
            return self.start + frac * (self.end - self.start)
        return self.end + (self.start - self.end) * float(np.exp(-t / self.decay_steps))

    def describe(self) -> dict[str, object]:
        """The schedule as plain values (for results and summaries)."""
        return {
            "kind": self.kind.value,
            "start": self.start,
            "end": self.end,
            "decay_steps": self.decay_steps,
        }


@dataclass(frozen=True)
class LearnerParams:
    """Hyper-parameters shared by the learners.

    Attributes
    ----------
    alpha : float
        Learning rate of the tabular learners in ``(0, 1]``: the fraction of the TD error by
        which an update moves ``Q(s, a)`` (``linear`` and ``dqn`` have their own step sizes in
        their configurations).
    gamma : float
        Discount factor in ``[0, 1)`` (every learner).
    epsilon : EpsilonSchedule
        Exploration schedule (every learner).
    initial_q : float
        Initial value of every table entry (``linear``: of every action value; unused by
        ``dqn``).
    """

    alpha: float = 0.2
    gamma: float = 0.95
    epsilon: EpsilonSchedule = field(default_factory=EpsilonSchedule)
    initial_q: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha <= 1.0:
            raise ValueError(f"alpha must be in (0, 1], got {self.alpha}")
        if not 0.0 <= self.gamma < 1.0:
            raise ValueError(f"gamma must be in [0, 1), got {self.gamma}")
