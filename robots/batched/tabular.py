"""Compiled tabular learning for the batched simulator: Q-learning and SARSA for many robots.

The maths and the order of random draws are those of :mod:`dfrl.robots.learners` and
:class:`dfrl.robots.training.Trainer.step` (update, then choose; SARSA chooses first), on the
tables ``q[i]`` of every robot ``i`` (shape (n, n_states, n_actions)). :func:`train` runs
``steps`` iterations of every robot without returning to Python.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from dfrl.robots.batched import kernels as K
from dfrl.robots.batched.shuffle import M_CAPACITY, learnt_outcome

#: Learner codes of :data:`ALGOS` in the ``algo`` array.
QLEARNING, SARSA = 0, 1
ALGOS: dict[str, int] = {"qlearning": QLEARNING, "sarsa": SARSA}
#: Epsilon schedule kinds (``dfrl.robots.td.ScheduleKind``) in column 0 of ``eps``.
SCHEDULES: dict[str, int] = {"constant": 0, "linear": 1, "exponential": 2}
#: Columns of the per-robot statistics ``stats``.
S_REWARD, S_COLLISIONS, S_RESPAWNS, S_QSUM = 0, 1, 2, 3
N_STATS = 4
#: Fields recorded per step when asked (``record``, shape (n, steps, N_RECORD)).
RECORD_FIELDS: tuple[str, ...] = ("reward", "collided", "q_sum", "state", "action", "x", "y")
N_RECORD = len(RECORD_FIELDS)


@njit(cache=True)
def epsilon(eps, t):
    """Exploration probability after ``t`` updates (``EpsilonSchedule.value``)."""
    kind, start, end, decay = eps[0], eps[1], eps[2], eps[3]
    if kind == 0.0:
        return start
    if kind == 1.0:
        return start + min(t / decay, 1.0) * (end - start)
    return end + (start - end) * math.exp(-t / decay)


@njit(cache=True)
def greedy(row, rng):
    """An action of highest value, ties broken with ``rng`` (``td.greedy_action``)."""
    top = row[0]
    for a in range(1, row.shape[0]):
        if row[a] > top:
            top = row[a]
    ties = 0
    for a in range(row.shape[0]):
        if row[a] == top:
            ties += 1
    pick = 0 if ties == 1 else rng.integers(0, ties)
    for a in range(row.shape[0]):
        if row[a] == top:
            if pick == 0:
                return a
            pick -= 1
    return 0


@njit(cache=True)
def choose(row, eps_value, rng):
    """Epsilon-greedy (``td.epsilon_greedy``)."""
    if eps_value > 0.0 and rng.random() < eps_value:
        return rng.integers(0, row.shape[0])
    return greedy(row, rng)


@njit(cache=True)
def update(q, visits, t, stats, i, s, a, target, alpha):
    """``q[i, s, a] += alpha * (target - q[i, s, a])``, counted."""
    old = q[i, s, a]
    new = old + alpha * (target - old)
    q[i, s, a] = new
    visits[i, s, a] += 1
    t[i] += 1
    stats[i, S_QSUM] += new - old


@njit(cache=True)
def learn(i, algo, q, visits, t, stats, s, a, r, ns, terminal, alpha, gamma, eps, rng):
    """One TD update of robot ``i`` and its next action in ``ns``."""
    if algo == SARSA:
        na = choose(q[i, ns], epsilon(eps, t[i]), rng)
        target = r if terminal else r + gamma * q[i, ns, na]
        update(q, visits, t, stats, i, s, a, target, alpha)
        return na
    if terminal:
        target = r
    else:
        best = q[i, ns, 0]
        for b in range(1, q.shape[2]):
            if q[i, ns, b] > best:
                best = q[i, ns, b]
        target = r + gamma * best
    update(q, visits, t, stats, i, s, a, target, alpha)
    return choose(q[i, ns], epsilon(eps, t[i]), rng)


@njit(cache=True)
def train(
    steps,
    algo,
    alpha,
    gamma,
    eps,
    q,
    visits,
    t,
    state,
    action,
    stats,
    record,
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
    groups,
    P,
    I,
    env_rngs,
    motion_rngs,
    learner_rngs,
    sh_buffer,
    sh_meta,
    sh_total,
    sh_rngs,
):
    """``steps`` iterations of every robot: act, simulate, update, choose (a respawn after a
    collision or when stuck). ``record`` of shape (n, steps, N_RECORD) is filled when it has
    ``steps`` rows (pass shape (n, 0, N_RECORD) not to record). Returns the first robot whose
    arena had no free pose left, or -1. Robots with ``sh_meta[i, M_CAPACITY] > 0`` learn from
    the control's outcomes (:mod:`.shuffle`, drawn from ``sh_rngs[i]``)."""
    out = np.zeros(4)
    rng_ = P[K.P_SENSOR_RANGE]
    levels = I[K.I_LEVELS]
    keep = record.shape[1] == steps
    for i in range(q.shape[0]):
        er, mr, lr = env_rngs[i], motion_rngs[i], learner_rngs[i]
        for k in range(steps):
            s, a = state[i], action[i]
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
            x, y = pose[i, 0], pose[i, 1]
            terminated = collided and I[K.I_RESPAWN] == 1
            ns = K.discretise(dist[i], rng_, groups, levels)
            lr_r, lr_end = r, terminated
            if sh_meta[i, M_CAPACITY] > 0:
                lr_r, lr_end = learnt_outcome(
                    i, r, terminated, sh_buffer, sh_meta, sh_total, sh_rngs[i]
                )
            na = learn(
                i,
                algo[i],
                q,
                visits,
                t,
                stats,
                s,
                a,
                lr_r,
                ns,
                lr_end,
                alpha[i],
                gamma[i],
                eps[i],
                lr,
            )
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
                ns = K.discretise(dist[i], rng_, groups, levels)
                na = choose(q[i, ns], epsilon(eps[i], t[i]), lr)
                stats[i, S_RESPAWNS] += 1
            state[i], action[i] = ns, na
            stats[i, S_REWARD] += r
            stats[i, S_COLLISIONS] += 1.0 if collided else 0.0
            if keep:
                rec = record[i, k]
                rec[0], rec[1], rec[2] = r, 1.0 if collided else 0.0, stats[i, S_QSUM]
                rec[3], rec[4], rec[5], rec[6] = s, a, x, y
    return -1
