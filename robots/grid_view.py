"""A function learner seen as a Q-table on the discretised state grid: the common representation
of a heterogeneous federation (tabular and function learners under one agent).

The tabular learners' states (:mod:`dfrl.robots.state`, default 81 states x 3 actions) are the
grid. A function learner (``linear``, ``dqn``) is turned into a table of that shape by
:class:`GridView`:

* **get** (``q_table``): its Q-function evaluated at one representative observation per state,
  the **centre of the state's cell** in the 8-reading space (:func:`grid_points`): every sensor
  of a group at level ``k >= 1`` reads the middle of the level's band, ``(k - 1/2)/(levels - 1)``
  (0.25 or 0.75 with 3 levels), at level 0 it reads 0 (nothing in range), and the sensors no
  group uses (the rear ones) read 0. The points are fixed by the discretisation alone, so a
  grid view can be rebuilt from a saved parameter vector (:func:`grid_table`), and every
  centre maps back to its own state (tested).
* **set** (``set_q_table``): distillation towards the table (:func:`dfrl.robots.distill.distil`:
  a few Adam steps, autograd gradients, bounded cost), every state weighted alike. The residual
  of the last one is kept (:attr:`GridView.last_distillation`).
* **visits**: the transitions the learner learnt from, counted per (state, action) of the
  grid from the moment the view was made (the weights of ``visit_average``).

Why the centre and not, say, the mean of the observations the robot saw in a state: it needs no
state of its own (nothing to checkpoint, the same points on every robot and after a restart),
it is what a file can be checked against, and it stays inside its cell (the mean of
observations of a cell whose value is a maximum over sensors need not).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dfrl.robots.approx import FunctionLearner, Layout
from dfrl.robots.distill import DistilConfig, DistilReport, distil
from dfrl.robots.state import Discretiser

__all__ = ["GridView", "grid_points", "grid_table"]


def grid_points(discretiser: Discretiser, obs_dim: int = 8) -> np.ndarray:
    """The centre of every state's cell (see the module doc).

    Parameters
    ----------
    discretiser : Discretiser
    obs_dim : int
        Length of an observation (every group's sensors must be below it).

    Returns
    -------
    np.ndarray, float64, shape (n_states, obs_dim)
        Row ``s`` maps to state ``s``.
    """
    top = discretiser.levels - 1
    if any(i >= obs_dim for g in discretiser.groups for i in g):
        raise ValueError(f"the grouping uses sensors beyond obs_dim {obs_dim}")
    points = np.zeros((discretiser.n_states, obs_dim), dtype=np.float64)
    for s in range(discretiser.n_states):
        rest = s
        for group in discretiser.groups:
            level = rest % discretiser.levels
            rest //= discretiser.levels
            if level:
                points[s, list(group)] = (level - 0.5) / top
    return points


def grid_table(learner: FunctionLearner, discretiser: Discretiser) -> np.ndarray:
    """A function learner's Q-values at :func:`grid_points`, shape (n_states, n_actions)."""
    return learner.q_batch(grid_points(discretiser, learner.obs_dim))


class GridView:
    """A robot with a function learner seen as a Q-table on the grid (see the module doc).

    A provider for the bridge (``q_table``, ``visits``, ``set_q_table``) that also passes the
    learner's parameters through (``params``, ``param_layout``, ``set_params``, ``samples``,
    ``learner_kind``), so the robot can be federated either way.

    Parameters
    ----------
    trainer : Trainer
        A :class:`dfrl.robots.training.Trainer` whose learner is a function learner
        (``trainer.learner``, ``trainer.discretiser``).
    config : DistilConfig, optional
        How a table is absorbed.

    Attributes
    ----------
    points : np.ndarray, shape (n_states, obs_dim)
    last_distillation : DistilReport or None
        The report of the last :meth:`set_q_table`.

    Raises
    ------
    TypeError
        The trainer's learner is not a function learner.
    """

    def __init__(self, trainer: Any, config: DistilConfig | None = None) -> None:
        learner = trainer.learner
        if not isinstance(learner, FunctionLearner):
            raise TypeError(f"a grid view is for a function learner, not {type(learner).__name__}")
        self.trainer = trainer
        self.learner: FunctionLearner = learner
        self.discretiser: Discretiser = trainer.discretiser
        self.config = config or DistilConfig()
        self.points = grid_points(self.discretiser, learner.obs_dim)
        self._visits = np.zeros((self.discretiser.n_states, learner.n_actions), dtype=np.int64)
        self.last_distillation: DistilReport | None = None
        learner.watchers.append(self._seen)

    def _seen(self, obs: np.ndarray, action: int) -> None:
        self._visits[self.discretiser(obs), action] += 1

    # -- the table view ------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """(n_states, n_actions)."""
        return (int(self._visits.shape[0]), int(self._visits.shape[1]))

    @property
    def q_table(self) -> np.ndarray:
        """The learner's values at the grid points, a new float64 array (n_states, n_actions)."""
        return self.learner.q_batch(self.points)

    @property
    def visits(self) -> np.ndarray:
        """Transitions learnt from per (state, action) since the view was made (a copy)."""
        return self._visits.copy()

    def set_q_table(self, table: np.ndarray) -> None:
        """Distil ``table`` into the learner (its report in :attr:`last_distillation`).

        Raises
        ------
        ValueError
            Wrong shape or a non-finite entry (the learner is unchanged).
        """
        arr = np.asarray(table, dtype=np.float64)
        if arr.shape != self.shape:
            raise ValueError(f"Q-table shape {arr.shape} does not match the grid's {self.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("Q-table has a non-finite entry")
        self.last_distillation = distil(self.learner, self.points, arr, config=self.config)

    def read_table(self) -> np.ndarray:
        """An agent's read of the table view (the bridge's verb pair; README, "Words")."""
        return self.q_table

    def write_table(self, table: np.ndarray, origin: Any = None) -> None:
        """An agent's write of the table view: :meth:`set_q_table` (distilled)."""
        self.set_q_table(table)

    # -- the parameters, passed through --------------------------------------------------------
    @property
    def params(self) -> np.ndarray:
        return self.trainer.params

    @property
    def param_layout(self) -> Layout:
        return self.trainer.param_layout

    def set_params(self, vec: np.ndarray) -> None:
        self.trainer.set_params(vec)

    @property
    def samples(self) -> int:
        return self.trainer.samples

    @property
    def learner_kind(self) -> str:
        return self.trainer.learner_kind

    def __repr__(self) -> str:
        return f"<GridView {self.learner.name} {self.shape}>"
