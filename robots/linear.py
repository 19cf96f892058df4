"""``linear``: linear Q over tile-coded sensors, trained by semi-gradient Q-learning.

The model is ``Q(x, a) = w[a] . phi(x)`` with ``phi`` the binary feature map of
:mod:`dfrl.robots.features` (a bias plus a 1-D tile coding of each IR proximity; ``n_active``
ones). One transition ``(x, a, r, x', terminal)`` moves the weights of ``a``'s active features:

    target = r + gamma * max_a' Q(x', a')           (r when terminal)
    w[a, i] += (alpha / n_active) * (target - Q(x, a))     for every active i

which is the semi-gradient step ``w[a] += (alpha / n_active) * delta * grad_w Q(x, a)`` (the
gradient of a linear model is its feature vector). Dividing by the number of active features
makes ``alpha`` mean what it means for the tabular learners: ``Q(x, a)`` moves the fraction
``alpha`` of the way to the target (:func:`semi_gradient_update`). ``alpha`` is the learner's
own (:class:`LinearConfig`, default 0.05: every update also moves the values of all the
observations that share a tile, so it is smaller than the tables' 0.2; with 0.2 one seed in
five learnt to spin in place, robots/README.md). Initial weights: the bias
weight of every action is ``initial_q``, the others 0, so ``Q`` starts at ``initial_q``
everywhere as a tabular learner's table does. Parameters for the federated layer:
``[("w", (n_actions, n_features))]``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from dataclasses import dataclass

from dfrl.robots.approx import FunctionLearner, Layout, QModel, validate_params
from dfrl.robots.features import TileCoding, active_features, feature_matrix
from dfrl.robots.td import q_learning_target

if TYPE_CHECKING:
    from dfrl.robots.td import LearnerParams


@dataclass(frozen=True)
class LinearConfig:
    """Hyper-parameters of :class:`LinearQ` (``gamma``, ``epsilon`` and ``initial_q`` come from
    ``LearnerParams``).

    Attributes
    ----------
    alpha : float
        Fraction of the TD error by which an update moves ``Q(x, a)``, in ``(0, 1]``.
    tilings, tiles : int
        The feature map (:class:`dfrl.robots.features.TileCoding`).
    """

    alpha: float = 0.05
    tilings: int = 4
    tiles: int = 8

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha <= 1.0:
            raise ValueError(f"alpha must be in (0, 1], got {self.alpha}")
        self.coding()  # checks tilings and tiles

    def coding(self) -> TileCoding:
        """The feature map."""
        return TileCoding(self.tilings, self.tiles)


def linear_q(weights: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Action values of a binary feature vector given by its active indices.

    Parameters
    ----------
    weights : np.ndarray, shape (n_actions, n_features)
    active : np.ndarray of int, shape (n_active,)

    Returns
    -------
    np.ndarray, shape (n_actions,)
        ``weights[:, active].sum(axis=1)``.
    """
    return weights[:, active].sum(axis=1)


def semi_gradient_update(active_weights: np.ndarray, target: float, alpha: float) -> np.ndarray:
    """New values of one action's active weights after a semi-gradient step.

    With ``q = active_weights.sum()`` (the action's value) every weight moves by
    ``alpha / n_active * (target - q)``, so the new sum is ``q + alpha * (target - q)``.

    Parameters
    ----------
    active_weights : np.ndarray, shape (n_active,)
        ``w[a, active]``.
    target : float
    alpha : float
        Fraction of the TD error by which ``Q(x, a)`` moves.
    """
    q = float(active_weights.sum())
    return active_weights + (alpha / active_weights.shape[0]) * (target - q)


class LinearQ(FunctionLearner):
    """Semi-gradient Q-learning with a linear model over tile-coded proximities.

    Parameters
    ----------
    obs_dim, n_actions : int
    params : LearnerParams
        ``gamma``, ``epsilon``, ``initial_q`` (the bias weights' initial value); ``alpha`` is
        not used (see ``config``).
    rng : np.random.Generator
        Exploration only (the initial weights are fixed).
    config : LinearConfig, optional
        Step size and feature map (default 0.05, 4 tilings x 8 tiles per sensor);
        ``TrainerConfig.linear``.

    Attributes
    ----------
    weights : np.ndarray, float64, shape (n_actions, n_features)
        Live weights.
    """

    name = "linear"
    config_field = "linear"

    def __init__(
        self,
        obs_dim: int,
        n_actions: int,
        params: "LearnerParams",
        rng: np.random.Generator,
        config: LinearConfig | None = None,
    ) -> None:
        super().__init__(obs_dim, n_actions, params, rng)
        self.config = config or LinearConfig()
        self.coding = self.config.coding()
        self.weights = np.zeros((n_actions, self.coding.n_features(obs_dim)), dtype=np.float64)
        self.weights[:, 0] = params.initial_q
        self._cache: tuple[bytes, np.ndarray] | None = None

    def _active(self, obs: np.ndarray) -> np.ndarray:
        # the next observation of one step is the observation of the next: code it once
        key = np.asarray(obs, dtype=np.float64).tobytes()
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, active_features(obs, self.coding))
        return self._cache[1]

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        return linear_q(self.weights, self._active(obs))

    def learn(
        self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, terminal: bool
    ) -> int:
        self._observed(obs, action)
        active = self._active(obs)
        next_q = self.q_values(next_obs)
        target = q_learning_target(reward, next_q, self.params.gamma, terminal)
        self.weights[action, active] = semi_gradient_update(
            self.weights[action, active], target, self.config.alpha
        )
        self.t += 1
        return self.select_action(next_obs)

    def q_model(self) -> tuple[list[np.ndarray], QModel]:
        """``[weights]`` and ``Q(x, .) = phi(x) @ weights.T`` over a batch (the feature matrix
        of the batch is computed with numpy: it does not depend on the weights)."""
        coding = self.coding
        cache: dict[bytes, np.ndarray] = {}  # the last batch's features

        def model(arrays: list, x: np.ndarray, xp: object = np) -> object:
            key = np.ascontiguousarray(x, dtype=np.float64).tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = feature_matrix(x, coding)
            return cache[key] @ arrays[0].T

        return [self.weights], model

    @property
    def param_layout(self) -> Layout:
        return [("w", tuple(self.weights.shape))]

    def get_params(self) -> np.ndarray:
        return self.weights.ravel().copy()

    def set_params(self, vec: np.ndarray) -> None:
        self.weights[...] = validate_params(vec, self.param_layout).reshape(self.weights.shape)
