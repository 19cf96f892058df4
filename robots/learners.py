"""Tabular learners as plug-ins: the maths as pure functions, the learners as small classes.

A learner owns a Q-table ``q`` (float64, shape (n_states, n_actions)) and a visit count
``visits`` (int64, same shape: number of updates of each state-action pair). It is driven by
two calls:

* ``select_action(state) -> action`` (epsilon-greedy on the current table);
* ``learn(state, action, reward, next_state, terminal) -> next_action``: one TD update of
  ``q[state, action]`` and the action to take in ``next_state``. Q-learning updates first and
  then chooses; SARSA chooses first and bootstraps on that choice.

New learners subclass :class:`TabularLearner` and register in :data:`LEARNERS`.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from enum import Enum
from typing import ClassVar

import numpy as np


# -- pure maths ----------------------------------------------------------------------------
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


@dataclass(frozen=True)
class LearnerParams:
    """Hyper-parameters shared by the tabular learners.

    Attributes
    ----------
    alpha : float
        Learning rate in ``(0, 1]``.
    gamma : float
        Discount factor in ``[0, 1)``.
    epsilon : EpsilonSchedule
        Exploration schedule.
    initial_q : float
        Initial value of every table entry.
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


def validate_table(table: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Check a Q-table's shape and values; return it as a float64 array (a copy).

    Raises
    ------
    ValueError
        Wrong shape or non-finite entries.
    """
    arr = np.array(table, dtype=np.float64, copy=True)
    if arr.shape != tuple(shape):
        raise ValueError(f"Q-table shape {arr.shape} does not match the expected {tuple(shape)}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"Q-table has a non-finite entry at (state, action) = {tuple(int(i) for i in bad)}")
    return arr


class TabularLearner(ABC):
    """Base of the tabular learners.

    Parameters
    ----------
    n_states, n_actions : int
        Table shape.
    params : LearnerParams
        Hyper-parameters.
    rng : np.random.Generator
        Source of exploration randomness.
    """

    #: Registry name.
    name: ClassVar[str] = ""

    def __init__(self, n_states: int, n_actions: int, params: LearnerParams,
                 rng: np.random.Generator) -> None:
        self.params = params
        self.rng = rng
        self.q = np.full((n_states, n_actions), params.initial_q, dtype=np.float64)
        self.visits = np.zeros((n_states, n_actions), dtype=np.int64)
        self.t = 0
        self.greedy = False  #: when True, select_action never explores

    @property
    def epsilon(self) -> float:
        """Current exploration probability."""
        return 0.0 if self.greedy else self.params.epsilon.value(self.t)

    def select_action(self, state: int) -> int:
        """Epsilon-greedy action in ``state``."""
        return epsilon_greedy(self.q[state], self.epsilon, self.rng)

    def set_table(self, table: np.ndarray) -> None:
        """Replace the table in place after validation (shape, finiteness)."""
        self.q[...] = validate_table(table, self.q.shape)

    @abstractmethod
    def learn(self, state: int, action: int, reward: float, next_state: int, terminal: bool) -> int:
        """Update ``q[state, action]`` and return the next action (in ``next_state``)."""

    def _apply(self, state: int, action: int, target: float) -> float:
        old = self.q[state, action]
        new = td_update(old, target, self.params.alpha)
        self.q[state, action] = new
        self.visits[state, action] += 1
        self.t += 1
        return new - old


class QLearning(TabularLearner):
    """Off-policy TD control: bootstrap on the best next action."""

    name = "qlearning"

    def learn(self, state: int, action: int, reward: float, next_state: int, terminal: bool) -> int:
        target = q_learning_target(reward, self.q[next_state], self.params.gamma, terminal)
        self._apply(state, action, target)
        return self.select_action(next_state)


class Sarsa(TabularLearner):
    """On-policy TD control: bootstrap on the next action actually chosen."""

    name = "sarsa"

    def learn(self, state: int, action: int, reward: float, next_state: int, terminal: bool) -> int:
        next_action = self.select_action(next_state)
        target = sarsa_target(reward, self.q[next_state, next_action], self.params.gamma, terminal)
        self._apply(state, action, target)
        return next_action


#: Registered learners by name; the CLI offers its keys as choices.
LEARNERS: dict[str, type[TabularLearner]] = {
    QLearning.name: QLearning,
    Sarsa.name: Sarsa,
}


def make_learner(name: str, n_states: int, n_actions: int, params: LearnerParams,
                 rng: np.random.Generator) -> TabularLearner:
    """Instantiate a registered learner.

    Raises
    ------
    KeyError
        Unknown learner name (the message lists the registered ones).
    """
    try:
        cls = LEARNERS[name]
    except KeyError:
        raise KeyError(f"unknown learner '{name}'; registered: {sorted(LEARNERS)}") from None
    return cls(n_states, n_actions, params, rng)
