"""Distillation: move a function learner's Q-values at given observations towards target values.

A function learner (:class:`dfrl.robots.approx.FunctionLearner`) that takes part in a
federation of Q-tables (:mod:`dfrl.robots.grid_view`) absorbs an aggregate table ``T`` (shape
(B, n_actions), one row per grid point ``x_b``) by a few full-batch Adam steps on the weighted
mean squared error

    L(theta) = sum_b w_b * mean_a (Q_theta(x_b, a) - T[b, a])**2 / sum_b w_b      (distil_loss)

starting from its current arrays ``theta`` (so what it knows between the grid points is moved,
not replaced). The gradient comes from autograd (``autograd.grad`` of :func:`distil_loss` with
respect to the arrays); the Adam bookkeeping is :class:`dfrl.robots.dqn.Adam`'s.

Defaults (:class:`DistilConfig`, measured in robots/README.md, "Heterogeneous federations"):
at most 300 steps, Adam step size 0.01 (``dqn``) or 0.02 (``linear``: its weights are per
tile and 33 of them sum to a value), stop early once the root mean squared residual is below
0.01. The cost is bounded by ``steps`` forward and backward passes over B = 81 points
(``dqn``: 300 steps took 0.35-0.46 s on the shared test machine). ``linear`` cannot
fit an arbitrary grid table (its values are a sum of one function per sensor): its residual
stops at the least-squares floor (measured in robots/README.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from dfrl.robots.dqn import Adam

if TYPE_CHECKING:
    from dfrl.robots.approx import FunctionLearner, QModel

__all__ = ["DistilConfig", "DistilReport", "distil", "distil_loss", "DEFAULT_LR"]

#: Adam step size per learner name when :attr:`DistilConfig.lr` is None.
DEFAULT_LR: dict[str, float] = {"dqn": 0.01, "linear": 0.02}


@dataclass(frozen=True)
class DistilConfig:
    """How a function learner absorbs a table (see the module doc).

    Attributes
    ----------
    steps : int
        Most Adam steps per distillation (the bound on its cost), >= 1.
    lr : float or None
        Adam step size; None: :data:`DEFAULT_LR` of the learner (1e-3 for one not listed).
    stop_rms : float
        Stop once the root mean squared residual (unweighted, over every entry) is at most this
        (0: always run ``steps``).
    """

    steps: int = 300
    lr: float | None = None
    stop_rms: float = 0.01

    def __post_init__(self) -> None:
        if int(self.steps) != self.steps or self.steps < 1:
            raise ValueError(f"steps must be an integer >= 1, got {self.steps}")
        if self.lr is not None and not self.lr > 0.0:
            raise ValueError(f"lr must be positive, got {self.lr}")
        if not self.stop_rms >= 0.0:
            raise ValueError(f"stop_rms must be >= 0, got {self.stop_rms}")

    def step_size(self, learner_name: str) -> float:
        """The Adam step size for a learner of that name."""
        return float(self.lr) if self.lr is not None else DEFAULT_LR.get(learner_name, 1e-3)


@dataclass(frozen=True)
class DistilReport:
    """What one distillation did.

    Attributes
    ----------
    steps : int
        Adam steps taken.
    rms_before, rms_after : float
        Root mean squared residual ``Q(x_b, a) - T[b, a]`` over every entry, before and after.
    max_after : float
        Largest absolute residual after.
    seconds : float
        Wall time.
    """

    steps: int
    rms_before: float
    rms_after: float
    max_after: float
    seconds: float


def distil_loss(
    model: "QModel",
    arrays: list[Any],
    x: np.ndarray,
    targets: np.ndarray,
    weights: np.ndarray,
    xp: Any = np,
) -> Any:
    """The weighted mean squared error of the module doc.

    Parameters
    ----------
    model : QModel
    arrays : list of arrays
        The model's arrays (autograd boxes while differentiating).
    x : np.ndarray, shape (B, obs_dim)
    targets : np.ndarray, shape (B, n_actions)
    weights : np.ndarray, shape (B,)
        Non-negative, not all zero.
    xp : module
        ``numpy`` or ``autograd.numpy``.
    """
    err = model(arrays, x, xp) - targets
    per_point = xp.mean(err * err, axis=1)
    return xp.sum(weights * per_point) / float(np.sum(weights))


def _residual(
    model: "QModel", arrays: list[np.ndarray], x: np.ndarray, targets: np.ndarray
) -> np.ndarray:
    return np.asarray(model(arrays, x, np), dtype=np.float64) - targets


def distil(
    learner: "FunctionLearner",
    x: np.ndarray,
    targets: np.ndarray,
    weights: np.ndarray | None = None,
    config: DistilConfig | None = None,
) -> DistilReport:
    """Move ``learner``'s values at ``x`` towards ``targets`` in place (see the module doc),
    then call its ``after_distil``.

    Parameters
    ----------
    learner : FunctionLearner
    x : np.ndarray, shape (B, obs_dim)
    targets : np.ndarray, shape (B, n_actions)
        Finite.
    weights : np.ndarray, shape (B,), optional
        Weight of each point (default: all 1).
    config : DistilConfig, optional

    Returns
    -------
    DistilReport

    Raises
    ------
    ValueError
        Shapes that do not fit, non-finite targets, negative or all-zero weights.
    """
    import autograd.numpy as anp
    from autograd import grad

    cfg = config or DistilConfig()
    x = np.asarray(x, dtype=np.float64)
    t = np.asarray(targets, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != learner.obs_dim:
        raise ValueError(f"points of shape {x.shape} do not fit obs_dim {learner.obs_dim}")
    if t.shape != (x.shape[0], learner.n_actions):
        raise ValueError(f"targets of shape {t.shape}, expected {(x.shape[0], learner.n_actions)}")
    if not np.all(np.isfinite(t)):
        raise ValueError("targets have a non-finite entry")
    w = np.ones(x.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (x.shape[0],) or np.any(w < 0) or not np.sum(w) > 0:
        raise ValueError("weights: one per point, >= 0, not all zero")
    t0 = time.perf_counter()
    arrays, model = learner.q_model()
    gradient = grad(lambda a: distil_loss(model, a, x, t, w, anp))
    adam = Adam.for_arrays(arrays, cfg.step_size(learner.name))
    res = _residual(model, arrays, x, t)
    before = float(np.sqrt(np.mean(res * res)))
    rms, steps = before, 0
    while steps < cfg.steps and rms > cfg.stop_rms:
        adam.step(arrays, gradient(arrays))
        steps += 1
        res = _residual(model, arrays, x, t)
        rms = float(np.sqrt(np.mean(res * res)))
    learner.after_distil()
    return DistilReport(
        steps=steps,
        rms_before=before,
        rms_after=rms,
        max_after=float(np.max(np.abs(res))),
        seconds=time.perf_counter() - t0,
    )
