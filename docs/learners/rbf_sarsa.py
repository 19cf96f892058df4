"""An example of bringing your own learner to dfrl: linear SARSA(lambda) over radial basis
features of the 8 IR proximities, written outside the package with numpy only.

The model is ``Q(x, a) = w[a] . phi(x)``, ``phi`` a bias plus, for every sensor, ``centres``
Gaussian bumps of width ``width`` over the proximity's range [0, 1], normalised to sum 1 per
sensor. SARSA(lambda) with accumulating eligibility traces: after the transition
``(x, a, r, x', a')``

    delta = r + gamma * Q(x', a') - Q(x, a)          (r - Q(x, a) when terminal)
    e     = gamma * lambda * e;   e[a] += phi(x)
    w    += (alpha / |phi(x)|^2) * delta * e

and the traces are cleared after a terminal transition. Federation averages ``w`` (FedAvg);
the traces are the robot's own and are cleared whenever the parameters are replaced.

Use it from a config (the path is resolved against the config's folder)::

    "learners": {"rbf_sarsa": {"class": "rbf_sarsa.py:RbfSarsa",
                               "options": {"alpha": 0.1, "lam": 0.8}}},
    "robots": [{"id": "r1", "arena": "r1", "algo": "rbf_sarsa"}, ...]

or install it with an entry point (``[project.entry-points."dfrl.learners"]
rbf_sarsa = "rbf_sarsa:RbfSarsa"``). robots/README.md, "Bring your own learner", lists what a
learner must offer.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from dfrl.robots.approx import FunctionLearner, validate_params


class RbfSarsa(FunctionLearner):
    """Linear SARSA(lambda) over radial basis features (see the module doc)."""

    name = "rbf_sarsa"

    def __init__(self, obs_dim: int, n_actions: int, params: Any, rng: np.random.Generator,
                 alpha: float = 0.1, lam: float = 0.8, centres: int = 5,
                 width: float = 0.15) -> None:
        super().__init__(obs_dim, n_actions, params, rng)
        if not 0.0 < alpha <= 1.0 or not 0.0 <= lam <= 1.0 or centres < 2 or width <= 0:
            raise ValueError("rbf_sarsa: alpha in (0, 1], lam in [0, 1], centres >= 2, "
                             "width > 0")
        self.alpha, self.lam, self.width = alpha, lam, width
        self.centres = np.linspace(0.0, 1.0, centres)
        n_features = 1 + obs_dim * centres
        self.weights = np.zeros((n_actions, n_features), dtype=np.float64)
        self.weights[:, 0] = params.initial_q
        self.traces = np.zeros_like(self.weights)

    def features(self, x: np.ndarray) -> np.ndarray:
        """``phi`` of a batch ``(B, obs_dim)`` -> ``(B, n_features)``."""
        x = np.clip(np.asarray(x, dtype=np.float64).reshape(-1, self.obs_dim), 0.0, 1.0)
        bumps = np.exp(-((x[:, :, None] - self.centres) / self.width) ** 2 / 2)
        bumps /= bumps.sum(axis=2, keepdims=True)
        return np.concatenate([np.ones((x.shape[0], 1)), bumps.reshape(x.shape[0], -1)], axis=1)

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        return self.weights @ self.features(obs)[0]

    def learn(self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray,
              terminal: bool) -> int:
        self._observed(obs, action)
        phi = self.features(obs)[0]
        next_action = self.select_action(next_obs)
        target = reward if terminal else reward + self.params.gamma * float(
            self.weights[next_action] @ self.features(next_obs)[0])
        delta = target - float(self.weights[action] @ phi)
        self.traces *= self.params.gamma * self.lam
        self.traces[action] += phi
        self.weights += (self.alpha / float(phi @ phi)) * delta * self.traces
        if terminal:
            self.traces[...] = 0.0
        self.t += 1
        return next_action

    def q_model(self):  # noqa: ANN201 - (arrays, model), see FunctionLearner.q_model
        features = self.features

        def model(arrays: list, x: np.ndarray, xp: object = np) -> object:
            return features(x) @ arrays[0].T

        return [self.weights], model

    def after_distil(self) -> None:
        self.traces[...] = 0.0

    @property
    def param_layout(self) -> list[tuple[str, tuple[int, ...]]]:
        return [("w", tuple(self.weights.shape))]

    def get_params(self) -> np.ndarray:
        return self.weights.ravel().copy()

    def set_params(self, vec: np.ndarray) -> None:
        self.weights[...] = validate_params(vec, self.param_layout).reshape(self.weights.shape)
        self.traces[...] = 0.0

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "alpha": self.alpha, "lam": self.lam,
                "centres": len(self.centres), "width": self.width}
