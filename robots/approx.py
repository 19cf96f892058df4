"""Learners over the raw observation: the base class and the flat parameter vector.

A function-approximation learner computes action values ``Q(x, .)`` from the observation ``x``
(the 8 IR proximities of :class:`dfrl.robots.env.EPuckEnv`, float64, shape (obs_dim,)) with a
model whose parameters are a few named arrays. It is driven like a tabular learner, with the
observation in place of the discrete state:

* ``select_action(x) -> action`` (epsilon-greedy on ``q_values(x)``);
* ``learn(x, action, reward, next_x, terminal) -> next_action``.

For the federated layer its parameters are one flat float64 vector, the arrays of
``param_layout`` (name, shape) concatenated in order, each in C order (:func:`flatten`,
:func:`unflatten`); ``set_params`` validates length and finiteness (:func:`validate_params`).

For a heterogeneous federation (:mod:`dfrl.robots.grid_view`) a learner also offers its model
as a differentiable function of its arrays (``q_model``), watchers told of every transition it
learns from (``watchers``), and ``after_distil`` (run after its arrays were moved by
:func:`dfrl.robots.distill.distil`).

New learners subclass :class:`FunctionLearner` and register in
:data:`dfrl.robots.learners.LEARNERS`.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from dfrl.robots.td import epsilon_greedy, greedy_action

if TYPE_CHECKING:
    from dfrl.robots.td import LearnerParams

#: Names and shapes of a model's arrays, in the order of the flat vector.
Layout = list[tuple[str, tuple[int, ...]]]

#: A model as a function of its arrays: ``(arrays, x (B, obs_dim), xp) -> Q (B, n_actions)``,
#: written with ``xp`` (``numpy`` or ``autograd.numpy``) so that autograd can differentiate it
#: with respect to the arrays.
QModel = Callable[[list[Any], np.ndarray, Any], Any]

#: Told of every transition a learner learns from: ``(observation, action)``.
Watcher = Callable[[np.ndarray, int], None]


def layout_size(layout: Layout) -> int:
    """Number of floats in a flat vector of ``layout``."""
    return int(sum(int(np.prod(shape, dtype=np.int64)) for _, shape in layout))


def flatten(arrays: list[np.ndarray]) -> np.ndarray:
    """Concatenate arrays (each in C order) into one new float64 vector."""
    if not arrays:
        return np.zeros(0, dtype=np.float64)
    return np.concatenate([np.asarray(a, dtype=np.float64).ravel(order="C") for a in arrays])


def unflatten(vec: np.ndarray, layout: Layout) -> list[np.ndarray]:
    """Split a flat vector into new float64 arrays of the layout's shapes (inverse of
    :func:`flatten`).

    Raises
    ------
    ValueError
        The vector's length differs from the layout's size.
    """
    vec = np.asarray(vec, dtype=np.float64)
    if vec.ndim != 1 or vec.shape[0] != layout_size(layout):
        raise ValueError(
            f"parameter vector of shape {vec.shape} does not fit the layout "
            f"({layout_size(layout)} floats: {layout})"
        )
    out, start = [], 0
    for _, shape in layout:
        n = int(np.prod(shape, dtype=np.int64))
        out.append(vec[start : start + n].reshape(shape).copy())
        start += n
    return out


def validate_params(vec: np.ndarray, layout: Layout) -> np.ndarray:
    """Check a flat parameter vector against a layout; return it as a new float64 array.

    Raises
    ------
    ValueError
        Not 1-D, wrong length, or a non-finite entry.
    """
    arr = np.array(vec, dtype=np.float64, copy=True)
    size = layout_size(layout)
    if arr.ndim != 1 or arr.shape[0] != size:
        raise ValueError(
            f"parameter vector of shape {arr.shape} does not fit the layout ({size} floats)"
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(
            f"parameter vector has a non-finite entry at index {int(np.argmax(~np.isfinite(arr)))}"
        )
    return arr


class FunctionLearner(ABC):
    """Base of the learners over the raw observation.

    Parameters
    ----------
    obs_dim : int
        Length of the observation vector.
    n_actions : int
    params : LearnerParams
        ``gamma`` and ``epsilon`` are used by every subclass; what ``alpha`` means is up to it.
    rng : np.random.Generator
        Source of all of the learner's randomness (initial weights, exploration, replay).

    Attributes
    ----------
    t : int
        Transitions learnt from so far (the epsilon schedule's clock).
    greedy : bool
        When True, :meth:`select_action` never explores.
    watchers : list of callables
        Each called with ``(observation, action)`` of every transition learnt from (by
        :meth:`learn`, before the update); e.g. a grid view's visit counts.
    """

    #: Registry name.
    name: ClassVar[str] = ""
    #: What :attr:`dfrl.robots.training.Trainer.learner_kind` reports.
    kind: ClassVar[str] = "function"
    #: The :class:`dfrl.robots.training.TrainerConfig` field passed as the ``config`` keyword
    #: (the learner's own hyper-parameters), or None.
    config_field: ClassVar[str | None] = None

    def __init__(
        self, obs_dim: int, n_actions: int, params: "LearnerParams", rng: np.random.Generator
    ) -> None:
        if obs_dim < 1 or n_actions < 1:
            raise ValueError("obs_dim and n_actions must be positive")
        self.obs_dim = obs_dim
        self.n_actions = n_actions
        self.params = params
        self.rng = rng
        self.t = 0
        self.greedy = False
        self.watchers: list[Watcher] = []

    @property
    def epsilon(self) -> float:
        """Current exploration probability."""
        return 0.0 if self.greedy else self.params.epsilon.value(self.t)

    @abstractmethod
    def q_values(self, obs: np.ndarray) -> np.ndarray:
        """Action values of one observation, float64, shape (n_actions,)."""

    def select_action(self, obs: np.ndarray) -> int:
        """Epsilon-greedy action for ``obs``."""
        return epsilon_greedy(self.q_values(obs), self.epsilon, self.rng)

    def act(self, obs: np.ndarray) -> int:
        """The learner interface's name for :meth:`select_action` (override that one)."""
        return self.select_action(obs)

    def describe(self) -> dict[str, Any]:
        """What the learner is and its settings, for results and summaries (a plug-in may add
        its own hyper-parameters: extend this dict)."""
        size = int(sum(int(np.prod(shape)) for _, shape in self.param_layout))
        return {
            "name": self.name,
            "kind": self.kind,
            "gamma": self.params.gamma,
            "epsilon": self.params.epsilon.describe(),
            "parameters": size,
            "layout": [[n, list(shape)] for n, shape in self.param_layout],
            "grid": self.distillable,
            **self._own_settings(),
        }

    def _own_settings(self) -> dict[str, Any]:
        own = getattr(self, "config", None)
        if dataclasses.is_dataclass(own) and not isinstance(own, type):
            return dataclasses.asdict(own)
        return {}

    def greedy_action(self, obs: np.ndarray) -> int:
        """A greedy action for ``obs`` (lowest index on ties), no randomness used."""
        return greedy_action(self.q_values(obs))

    @abstractmethod
    def learn(
        self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, terminal: bool
    ) -> int:
        """Learn from one transition and return the next action (for ``next_obs``); tells
        :attr:`watchers` first (:meth:`_observed`)."""

    def _observed(self, obs: np.ndarray, action: int) -> None:
        for watch in self.watchers:
            watch(obs, action)

    def q_model(self) -> tuple[list[np.ndarray], QModel]:
        """The live arrays the model's values depend on (moved in place by a distillation) and
        the model as a :data:`QModel` of them. Needed to join a grid federation only; a learner
        without it (this default) is refused there with a clear message.

        Raises
        ------
        NotImplementedError
            The learner does not offer its model.
        """
        raise NotImplementedError(
            f"learner {self.name!r} has no q_model(): it cannot join a "
            "grid federation (robots/README.md, 'Bring your own learner')"
        )

    @property
    def distillable(self) -> bool:
        """True when the learner offers :meth:`q_model` (can join a grid federation)."""
        return type(self).q_model is not FunctionLearner.q_model

    def q_batch(self, obs: np.ndarray) -> np.ndarray:
        """Action values of a batch of observations.

        Parameters
        ----------
        obs : np.ndarray, shape (B, obs_dim)

        Returns
        -------
        np.ndarray, float64, shape (B, n_actions)
        """
        x = np.asarray(obs, dtype=np.float64).reshape(-1, self.obs_dim)
        if not self.distillable:
            return np.array([self.q_values(row) for row in x], dtype=np.float64)
        arrays, model = self.q_model()
        return np.asarray(model(arrays, x, np), dtype=np.float64)

    def after_distil(self) -> None:  # noqa: B027 - an optional hook, doing nothing by default
        """Called after a distillation moved the arrays of :meth:`q_model` (default: nothing;
        ``dqn`` copies its online network into its target network)."""

    @property
    @abstractmethod
    def param_layout(self) -> Layout:
        """Names and shapes of the arrays in :meth:`get_params` order."""

    @abstractmethod
    def get_params(self) -> np.ndarray:
        """The parameters as one new flat float64 vector (see the module doc)."""

    @abstractmethod
    def set_params(self, vec: np.ndarray) -> None:
        """Replace the parameters from a flat vector.

        Raises
        ------
        ValueError
            Wrong length or a non-finite entry.
        """
