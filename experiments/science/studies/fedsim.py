"""Federated tabular learning in one process, for studies that need many runs.

The transfer and speed-up studies train hundreds of federations; starting robot process
processes and a mobile agent for each would cost more than the learning. :func:`federate`
runs the same thing in one process: ``N`` :class:`~dfrl.robots.training.Trainer` (one per
arena, seeded as the launcher seeds its robots), stepped in turn, and every ``respite``
iterations every table is replaced by the aggregate of all of them, which is what one sync
round of the dFRL agent does (it reads every table, folds them, writes the result back).
The aggregation maths are pure functions over arrays, registered by name in
:data:`AGGREGATIONS`; they mirror the agent's built-in methods (``average``, ``max``,
``visit_average``, platform_pl/dfrl_agent/dfrl_aggregation.pl) and the injectable ``max_visited``
(platform_pl/dfrl_agent/examples/max_visited.pl); tests check them against hand-computed tables.

The built-in three fold the tables as the agent's forward pass does, bit for bit: one table
after the other in itinerary order (the config's robot order), each element the C library's
operation (platform_pl/native/float_vectors.c): ``average`` adds ``((q1 + q2) + q3) ...`` and
divides the sum by the count; ``max`` keeps the aggregate unless it is below the next value
(``(p < q) ? q : p``, so of 0.0 and -0.0 the first one stays); ``visit_average`` folds
``q * w``, ``w`` (visit counts as float64) and ``q`` the same way and takes ``qw / w`` where
``w > 0``, else ``q / n``. With the same seeds a sync run of the agent (``dfrl run``) and
:func:`federate` give the same tables, curves and table history
(:mod:`dfrl.experiments.science.fed_replicas`, tested in ``test_fedsim_identity.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from dfrl.robots.training import StepMetrics, Trainer, TrainerConfig

Aggregation = Callable[[Sequence[np.ndarray], Sequence[np.ndarray]], np.ndarray]
#: Called every ``observe_every`` iterations with the iteration (per robot) and the trainers
#: (after any share at that iteration); returns True to stop the federation there.
Observer = Callable[[int, Sequence[Trainer]], bool]
#: Called after every step of every robot with the robot's index and the step's metrics.
StepHook = Callable[[int, StepMetrics], None]
#: Called after every share with the iteration (per robot) and the trainers, each holding the
#: aggregate (what a robot process records at a share: its table history).
ShareHook = Callable[[int, Sequence[Trainer]], None]


def _check(
    tables: Sequence[np.ndarray], visits: Sequence[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    if not tables:
        raise ValueError("nothing to aggregate")
    q = np.stack([np.asarray(t, dtype=np.float64) for t in tables])
    w = np.stack([np.asarray(v, dtype=np.float64) for v in visits])
    if q.shape != w.shape:
        raise ValueError(f"tables {q.shape} and visit counts {w.shape} differ in shape")
    if not np.isfinite(q).all():
        raise ValueError("a table holds a non-finite value")
    return q, w


def _fold(arrays: np.ndarray, step: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """``step(step(a0, a1), a2) ...``: the agent's fold over its forward pass, in order."""
    acc = arrays[0].copy()
    for a in arrays[1:]:
        acc = step(acc, a)
    return acc


def _keep_unless_below(acc: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(acc < q) ? q : acc`` element-wise (the C library's max)."""
    return np.where(acc < q, q, acc)


def aggregate_average(tables: Sequence[np.ndarray], visits: Sequence[np.ndarray]) -> np.ndarray:
    """Element-wise mean, shape (n_states, n_actions): the tables added in order, divided by
    their count."""
    q, _ = _check(tables, visits)
    return _fold(q, np.add) / float(len(q))


def aggregate_max(tables: Sequence[np.ndarray], visits: Sequence[np.ndarray]) -> np.ndarray:
    """Element-wise maximum (of equal values, 0.0 and -0.0, the earlier table's)."""
    q, _ = _check(tables, visits)
    return _fold(q, _keep_unless_below)


def aggregate_visit_average(
    tables: Sequence[np.ndarray], visits: Sequence[np.ndarray]
) -> np.ndarray:
    """Mean weighted by visit counts; entries nobody visited get the plain mean."""
    q, w = _check(tables, visits)
    qw = _fold(q * w, np.add)
    tot = _fold(w, np.add)
    plain = _fold(q, np.add) / float(len(q))
    with np.errstate(invalid="ignore", divide="ignore"):
        weighted = qw / tot
    return np.where(tot > 0, weighted, plain)


def aggregate_max_visited(tables: Sequence[np.ndarray], visits: Sequence[np.ndarray]) -> np.ndarray:
    """Element-wise maximum over the robots that visited the entry; plain mean elsewhere."""
    q, w = _check(tables, visits)
    seen = w > 0
    best = np.where(seen, q, -np.inf).max(axis=0)
    return np.where(seen.any(axis=0), best, q.mean(axis=0))


#: Aggregation methods by name (the agent's names).
AGGREGATIONS: dict[str, Aggregation] = {
    "average": aggregate_average,
    "max": aggregate_max,
    "visit_average": aggregate_visit_average,
    "max_visited": aggregate_max_visited,
}


@dataclass
class Federation:
    """Outcome of :func:`federate`.

    Attributes
    ----------
    table : np.ndarray, shape (n_states, n_actions)
        Robot 0's table at the end: the aggregate every robot holds when the run ended
        with a share (always, unless ``final_share`` is False or an observer stopped it).
    visits : np.ndarray
        Visit counts summed over robots.
    snapshots : dict of int to np.ndarray
        Iteration (per robot) -> aggregate after the round ending there, every
        ``snapshot_every`` rounds and the last one.
    q_sum, reward : np.ndarray, shape (robots, iterations)
        Each robot's sum of Q-values and cumulative reward per iteration.
    collisions : np.ndarray, shape (robots,)
    iterations : int
        Iterations per robot done (below the budget when an observer stopped the run).
    """

    table: np.ndarray
    visits: np.ndarray
    snapshots: dict[int, np.ndarray] = field(default_factory=dict)
    q_sum: np.ndarray | None = None
    reward: np.ndarray | None = None
    collisions: np.ndarray | None = None
    iterations: int = 0


def federate(
    configs: Sequence[TrainerConfig],
    iterations: int,
    respite: int,
    method: str = "average",
    snapshot_every: int = 0,
    initial: np.ndarray | None = None,
    observe: Observer | None = None,
    observe_every: int = 0,
    final_share: bool = True,
    on_step: StepHook | None = None,
    on_share: ShareHook | None = None,
) -> Federation:
    """Train one robot per config for ``iterations`` steps each, aggregating every
    ``respite`` (a single config with ``method`` anything is a standalone run).

    Parameters
    ----------
    configs : sequence of TrainerConfig
        One per robot (arena, seed, learner, ...); all must have the same table shape.
    iterations, respite : int
    method : str
        A key of :data:`AGGREGATIONS`.
    snapshot_every : int
        Keep the aggregate every so many rounds (0: only the last).
    initial : np.ndarray, optional
        Start every robot from this table instead of zeros.
    observe, observe_every : Observer, int
        Measure the robots' tables every ``observe_every`` iterations (after the share due
        then, if any), e.g. their error against a reference on a grid finer than the share
        period; the observer returning True stops every robot there (``q_sum`` and
        ``reward`` then end at that iteration).
    final_share : bool
        Also share after the last iteration when it is not a multiple of ``respite`` (as the
        agent's last round does); False keeps every share on the ``respite`` schedule.
    on_step, on_share : StepHook, ShareHook, optional
        Record each step and each share as they happen (e.g. the files of a run folder:
        :func:`dfrl.experiments.science.fed_replicas.run_replica`).

    Raises
    ------
    KeyError
        Unknown method.
    ValueError
        Bad budget or tables of different shapes.
    """
    agg = AGGREGATIONS[method]
    if iterations < 1 or respite < 1:
        raise ValueError("iterations and respite must be >= 1")
    if observe is not None and observe_every < 1:
        raise ValueError("an observer needs observe_every >= 1")
    trainers = [Trainer(c) for c in configs]
    try:
        if initial is not None:
            for t in trainers:
                t.set_q_table(initial)
        n = len(trainers)
        q_sum = np.zeros((n, iterations))
        reward = np.zeros((n, iterations))
        snaps: dict[int, np.ndarray] = {}
        rounds = 0
        done = iterations
        for i in range(iterations):
            for k, t in enumerate(trainers):
                m = t.step()
                q_sum[k, i], reward[k, i] = m.q_sum, m.cumulative_reward
                if on_step is not None:
                    on_step(k, m)
            if (i + 1) % respite == 0 or (final_share and i + 1 == iterations):
                table = agg([t.q_table for t in trainers], [t.visits for t in trainers])
                for t in trainers:
                    t.set_q_table(table)
                if on_share is not None:
                    on_share(i + 1, trainers)
                rounds += 1
                if (snapshot_every and rounds % snapshot_every == 0) or i + 1 == iterations:
                    snaps[i + 1] = table.copy()
            if observe is not None and (i + 1) % observe_every == 0 and observe(i + 1, trainers):
                done = i + 1
                break
        return Federation(
            table=trainers[0].q_table.copy(),
            visits=np.sum([t.visits for t in trainers], axis=0),
            snapshots=snaps,
            q_sum=q_sum[:, :done],
            reward=reward[:, :done],
            collisions=np.array([t.collisions for t in trainers]),
            iterations=done,
        )
    finally:
        for t in trainers:
            t.close()


def in_turn(config: TrainerConfig, arenas: Sequence[str], iterations: int) -> np.ndarray:
    """One robot trained ``iterations`` steps in each of ``arenas``, one after the other,
    keeping its table (and its exploration schedule restarting in each arena); the final table."""
    table: np.ndarray | None = None
    for k, arena in enumerate(arenas):
        with Trainer(config.replace(arena=arena, seed=config.seed + 1000 * k)) as t:
            if table is not None:
                t.set_q_table(table)
            for _ in range(iterations):
                t.step()
            table = t.q_table.copy()
    assert table is not None, "no arena given"
    return table
