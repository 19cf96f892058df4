"""The ``linear`` learner batched: semi-gradient Q-learning over tile-coded proximities for many
robots, in the compiled loop of the batched simulator.

The maths, the feature map and the order of random draws are those of
:class:`dfrl.robots.linear.LinearQ` and :class:`dfrl.robots.training.Trainer.step`: the active
features of an observation (the bias and one tile per sensor and tiling,
:mod:`dfrl.robots.features`), ``Q(x, a)`` the sum of ``a``'s weights over them, the target from
the next observation's values before the update, every active weight of the action moved by
``alpha / n_active`` of the TD error, then the epsilon-greedy choice on the updated weights.
(Sums run left to right here where numpy sums pairwise: values agree to rounding, not bit for
bit.) :class:`BatchedLinearTrainer` holds the weights of every robot, shape
``(n, n_actions, n_features)``, the layout of ``Trainer.params``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from dfrl.robots.approx import validate_params
from dfrl.robots.batched import kernels as K
from dfrl.robots.batched import tabular as T
from dfrl.robots.batched.shuffle import M_CAPACITY, learnt_outcome
from dfrl.robots.batched.training import RobotBatch
from dfrl.robots.training import TrainerConfig

#: The learner this module batches (code 0 in ``algo``).
LINEAR: dict[str, int] = {"linear": 0}


@njit(cache=True)
def active_features(dist_row, sensor_range, tilings, tiles, out):
    """Fill ``out`` (length ``1 + n_sensors * tilings``) with the active feature indices of
    the observation of ``dist_row`` (``features.active_features``)."""
    out[0] = 0
    k = 1
    for i in range(dist_row.shape[0]):
        p = min(max(np.float64(K.proximity(dist_row[i], sensor_range)), 0.0), 1.0)
        for t in range(tilings):
            tile = min(int(np.floor(p * (tiles - 1) + t / tilings)), tiles - 1)
            out[k] = 1 + (i * tilings + t) * tiles + tile
            k += 1


@njit(cache=True)
def values(w, i, active, out):
    """``out[a] = Q(x, a)`` of robot ``i`` for the features ``active``."""
    for a in range(w.shape[1]):
        s = 0.0
        for j in range(active.shape[0]):
            s += w[i, a, active[j]]
        out[a] = s


@njit(cache=True)
def train(
    steps,
    alpha,
    gamma,
    eps,
    w,
    t,
    action,
    stats,
    pose,
    prev,
    dist,
    trail,
    trail_len,
    trail_head,
    arena,
    first,
    count,
    half,
    boxes,
    angles,
    motion,
    P,
    I,
    tilings,
    tiles,
    env_rngs,
    motion_rngs,
    learner_rngs,
    sh_buffer,
    sh_meta,
    sh_total,
    sh_rngs,
):
    """``steps`` iterations of every linear robot (see :func:`.tabular.train`). Returns the
    first robot whose arena had no free pose left, or -1."""
    out = np.zeros(4)
    rng_ = P[K.P_SENSOR_RANGE]
    n_active = 1 + angles.shape[0] * tilings
    now = np.zeros(n_active, dtype=np.int64)
    nxt = np.zeros(n_active, dtype=np.int64)
    qn = np.zeros(w.shape[1])
    for i in range(w.shape[0]):
        er, mr, lr = env_rngs[i], motion_rngs[i], learner_rngs[i]
        active_features(dist[i], rng_, tilings, tiles, now)
        for _ in range(steps):
            a = action[i]
            K.move(
                i,
                a,
                pose,
                prev,
                dist,
                trail,
                trail_len,
                trail_head,
                arena,
                first,
                count,
                boxes,
                angles,
                motion,
                P,
                I,
                er,
                mr,
                out,
            )
            r, collided, stuck = out[0], out[1] > 0.0, out[2] > 0.0
            terminated = collided and I[K.I_RESPAWN] == 1
            active_features(dist[i], rng_, tilings, tiles, nxt)
            lr_r, lr_end = r, terminated
            if sh_meta[i, M_CAPACITY] > 0:
                lr_r, lr_end = learnt_outcome(
                    i, r, terminated, sh_buffer, sh_meta, sh_total, sh_rngs[i]
                )
            values(w, i, nxt, qn)
            target = lr_r
            if not lr_end:
                target = lr_r + gamma[i] * qn.max()
            q_sa = 0.0
            for j in range(n_active):
                q_sa += w[i, a, now[j]]
            step = alpha[i] / n_active * (target - q_sa)
            for j in range(n_active):
                w[i, a, now[j]] += step
            stats[i, T.S_QSUM] += step * n_active
            t[i] += 1
            values(w, i, nxt, qn)
            na = T.choose(qn, T.epsilon(eps[i], t[i]), lr)
            if terminated or stuck:
                if not K.respawn(
                    i,
                    pose,
                    prev,
                    dist,
                    trail,
                    trail_len,
                    trail_head,
                    arena,
                    first,
                    count,
                    half,
                    boxes,
                    angles,
                    P,
                    er,
                ):
                    return i
                active_features(dist[i], rng_, tilings, tiles, nxt)
                values(w, i, nxt, qn)
                na = T.choose(qn, T.epsilon(eps[i], t[i]), lr)
                stats[i, T.S_RESPAWNS] += 1
            now[:] = nxt
            action[i] = na
            stats[i, T.S_REWARD] += r
            stats[i, T.S_COLLISIONS] += 1.0 if collided else 0.0
    return -1


class BatchedLinearTrainer(RobotBatch):
    """``n`` robots learning with ``linear``, each as a :class:`~dfrl.robots.training.Trainer`
    would (one shared :class:`~dfrl.robots.linear.LinearConfig` feature map; step sizes may
    differ).

    Attributes
    ----------
    weights : np.ndarray, shape (n, n_actions, n_features)
        Every robot's live weights (``Trainer.params`` of robot ``i`` is ``weights[i].ravel()``).
    """

    def __init__(self, configs: Sequence[TrainerConfig], motion_noise: bool = True) -> None:
        super().__init__(configs, motion_noise, LINEAR)
        from dfrl.robots.batched.training import BatchError

        coding = configs[0].linear.coding()
        if any(c.linear.coding() != coding for c in configs):
            raise BatchError("one batch of linear robots shares its feature map (tilings, tiles)")
        self.tilings, self.tiles = coding.tilings, coding.tiles
        w, n = self.world, len(configs)
        self.alpha = np.array([c.linear.alpha for c in configs])
        self.weights = np.zeros((n, w.n_actions, coding.n_features(w.n_sensors)))
        self.weights[:, :, 0] = np.array([c.learner.initial_q for c in configs])[:, None]
        self.stats[:, T.S_QSUM] = self.weights.sum(axis=(1, 2))
        active = np.zeros(coding.n_active(w.n_sensors), dtype=np.int64)
        q = np.zeros(w.n_actions)
        self.action = np.zeros(n, dtype=np.int64)
        for i in range(n):
            w.start(i)
            active_features(w.dist[i], w.P[K.P_SENSOR_RANGE], self.tilings, self.tiles, active)
            values(self.weights, i, active, q)
            self.action[i] = T.choose(q, T.epsilon(self.eps[i], 0), self.learner_rngs[i])

    def run(self, steps: int) -> None:
        """Advance every robot by ``steps`` iterations.

        Raises
        ------
        ArenaError
            A robot's arena has no free pose left for a respawn.
        """
        if steps < 0:
            raise ValueError(f"steps must be >= 0, got {steps}")
        w, p = self.world, self.world.packed
        bad = train(
            steps,
            self.alpha,
            self.gamma,
            self.eps,
            self.weights,
            self.t,
            self.action,
            self.stats,
            w.pose,
            w.prev,
            w.dist,
            w.trail,
            w.trail_len,
            w.trail_head,
            w.arena,
            p.first,
            p.count,
            p.half,
            p.boxes,
            w.angles,
            w.motion,
            w.P,
            w.I,
            self.tilings,
            self.tiles,
            w.rngs,
            w.motion_rngs,
            self.learner_rngs,
            self.shuffle_buffer,
            self.shuffle_meta,
            self.shuffle_total,
            self.shuffle_rngs,
        )
        self._arena_full(bad)
        self.iteration += steps

    def params(self, i: int) -> np.ndarray:
        """Robot ``i``'s parameter vector (a copy), as ``Trainer.params``."""
        return self.weights[i].ravel().copy()

    def set_params(self, i: int, vec: np.ndarray) -> None:
        """Replace robot ``i``'s weights from a vector of ``Trainer.param_layout``.

        Raises
        ------
        ValueError
            Not 1-D, wrong length, or a non-finite entry.
        """
        layout = [("w", tuple(self.weights.shape[1:]))]
        self.weights[i] = validate_params(vec, layout).reshape(self.weights.shape[1:])
        self.stats[i, T.S_QSUM] = float(self.weights[i].sum())
