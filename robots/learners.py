"""Tabular learners as plug-ins: the maths as pure functions, the learners as small classes.

A learner owns a Q-table ``q`` (float64, shape (n_states, n_actions)) and a visit count
``visits`` (int64, same shape: number of updates of each state-action pair). It is driven by
two calls:

* ``select_action(state) -> action`` (epsilon-greedy on the current table);
* ``learn(state, action, reward, next_state, terminal) -> next_action``: one TD update of
  ``q[state, action]`` and the action to take in ``next_state``. Q-learning updates first and
  then chooses; SARSA chooses first and bootstraps on that choice.

New learners subclass :class:`TabularLearner` and register in :data:`LEARNERS`. The registry
also holds the learners over the raw observation (``linear``, :mod:`dfrl.robots.linear`;
``dqn``, :mod:`dfrl.robots.dqn`; base :class:`dfrl.robots.approx.FunctionLearner`), which
have no table; :func:`learner_kind` tells the two apart.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np

from dfrl.robots.approx import FunctionLearner
from dfrl.robots.dqn import DQN
from dfrl.robots.linear import LinearQ

# The pure maths live in dfrl.robots.td (shared with the function-approximation learners);
# they are imported here under their old home, where callers and tests find them.
from dfrl.robots.td import (
    EpsilonSchedule,  # noqa: F401 - re-exported, see above
    LearnerParams,
    ScheduleKind,  # noqa: F401 - re-exported, see above
    epsilon_greedy,
    greedy_action,  # noqa: F401 - re-exported, see above
    q_learning_target,
    sarsa_target,
    td_update,
)


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
        where = tuple(int(i) for i in bad)
        raise ValueError(f"Q-table has a non-finite entry at (state, action) = {where}")
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
    #: What :attr:`dfrl.robots.training.Trainer.learner_kind` reports.
    kind: ClassVar[str] = "tabular"

    def __init__(
        self, n_states: int, n_actions: int, params: LearnerParams, rng: np.random.Generator
    ) -> None:
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

    def act(self, state: int) -> int:
        """The learner interface's name for :meth:`select_action`."""
        return self.select_action(state)

    def set_table(self, table: np.ndarray) -> None:
        """Replace the table in place after validation (shape, finiteness)."""
        self.q[...] = validate_table(table, self.q.shape)

    @property
    def param_layout(self) -> list[tuple[str, tuple[int, ...]]]:
        """The table as the learner interface's one array: ``[("q", (n_states, n_actions))]``."""
        return [("q", tuple(self.q.shape))]

    def get_params(self) -> np.ndarray:
        """The table as a new flat float64 vector (C order)."""
        return self.q.ravel().copy()

    def set_params(self, vec: np.ndarray) -> None:
        """Replace the table from a flat vector (:meth:`get_params` order).

        Raises
        ------
        ValueError
            Wrong length or a non-finite entry.
        """
        arr = np.asarray(vec, dtype=np.float64)
        if arr.ndim != 1 or arr.size != self.q.size:
            raise ValueError(f"expected {self.q.size} parameters, got shape {arr.shape}")
        self.set_table(arr.reshape(self.q.shape))

    def describe(self) -> dict[str, Any]:
        """What the learner is and its settings, for results and summaries."""
        return {
            "name": self.name,
            "kind": self.kind,
            "alpha": self.params.alpha,
            "gamma": self.params.gamma,
            "epsilon": self.params.epsilon.describe(),
            "initial_q": self.params.initial_q,
            "shape": list(self.q.shape),
        }

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


#: Registered learners by name; the CLI offers its keys as choices and configs name them in
#: ``"algo"``. Tabular learners (``kind == "tabular"``) learn on the discretised state;
#: function-approximation learners (``kind == "function"``, :mod:`dfrl.robots.approx`) on the
#: raw observation, and have no Q-table: use :func:`is_tabular` before reaching for one.
LEARNERS: dict[str, type[TabularLearner] | type[FunctionLearner]] = {
    QLearning.name: QLearning,
    Sarsa.name: Sarsa,
    LinearQ.name: LinearQ,
    DQN.name: DQN,
}


def learner_class(name: str) -> type[TabularLearner] | type[FunctionLearner]:
    """The registered class of ``name``.

    Raises
    ------
    KeyError
        Unknown learner name (the message lists the built-in and plug-in ones).
    dfrl.robots.plugins.PluginError
        An installed plug-in of that name that does not load.
    """
    cls = LEARNERS.get(name)
    if cls is None:
        from dfrl.robots.plugins import find, plugin_names

        cls = find(name)
        if cls is None:
            raise KeyError(
                f"unknown learner '{name}'; built in: {sorted(LEARNERS)}; plug-ins: "
                f"{plugin_names() or 'none'} (robots/README.md, 'Bring your own "
                "learner')"
            )
    return cls


def learner_kind(name: str) -> str:
    """``"tabular"`` or ``"function"`` for a registered learner.

    Raises
    ------
    KeyError
        Unknown learner name (the message lists the registered ones).
    """
    return learner_class(name).kind


def is_tabular(name: str) -> bool:
    """True for a registered learner that keeps a Q-table (see :func:`learner_kind`)."""
    return learner_kind(name) == "tabular"


def make_learner(
    name: str,
    n_inputs: int,
    n_actions: int,
    params: LearnerParams,
    rng: np.random.Generator,
    **options: Any,
) -> TabularLearner | FunctionLearner:
    """Instantiate a registered learner.

    Parameters
    ----------
    name : str
        A key of :data:`LEARNERS`.
    n_inputs : int
        Number of states for a tabular learner, length of the observation otherwise.
    n_actions : int
    params : LearnerParams
    rng : np.random.Generator
    **options
        Passed to a function-approximation learner (``config=``: a
        :class:`dfrl.robots.linear.LinearConfig` for ``linear``, a
        :class:`dfrl.robots.dqn.DQNConfig` for ``dqn``); a tabular learner takes none.

    Raises
    ------
    KeyError
        Unknown learner name (the message lists the registered ones).
    TypeError
        Options given to a tabular learner.
    """
    cls = learner_class(name)
    if issubclass(cls, TabularLearner):
        if options:
            raise TypeError(f"tabular learner '{name}' takes no options, got {sorted(options)}")
        return cls(n_inputs, n_actions, params, rng)
    return cls(n_inputs, n_actions, params, rng, **options)
