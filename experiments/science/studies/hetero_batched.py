"""A run of ``dfrl hetero`` with its tabular robots on the batched simulator.

The batched simulator has tabular learners only, so :func:`run_one_batched` puts the
Q-learning robots of a run in one :class:`~dfrl.robots.batched.training.BatchedTrainer` and
keeps the dqn robot a pybullet :class:`~dfrl.robots.training.Trainer` seen through its
:class:`~dfrl.robots.grid_view.GridView`. Every comparison of the study keeps one simulator per
robot: the Q-learning robot is batched in ``ql_alone``, ``mixed`` and ``ql_pair``, the dqn robot
is pybullet in ``dqn_alone`` and ``mixed``; in ``mixed`` the two share as in
:func:`.hetero.run_one`. The robots do not interact between two shares, so each is stepped on
its own up to the next share or evaluation; the Q-tables are evaluated in one compiled call
(:func:`.history.eval_many`), the dqn in pybullet.
"""

from __future__ import annotations

import hashlib
import time
from typing import Any

from dfrl.experiments.science.studies.fedsim import AGGREGATIONS
from dfrl.experiments.science.studies.fedsim_batched import BatchedRobot, next_stop
from dfrl.experiments.science.studies.hetero import (
    EVAL_SEED,
    ROSTER,
    HeteroOptions,
    score_policy,
    share,
    trainer_config,
)
from dfrl.experiments.science.studies.history import eval_many
from dfrl.experiments.science.studies.simulators import BATCHED, PYBULLET

#: The simulator of each learner when the study runs batched.
SIMULATORS: dict[str, str] = {"qlearning": BATCHED, "dqn": PYBULLET}


def run_one_batched(run: str, seed: int, options: HeteroOptions) -> dict[str, Any]:
    """:func:`.hetero.run_one` with the Q-learning robots batched (see the module doc): the
    same rows, residuals, digests (sha256 of each robot's final parameters) and seconds."""
    from dfrl.robots.batched.training import BatchedTrainer
    from dfrl.robots.grid_view import GridView
    from dfrl.robots.training import Trainer

    t0 = time.perf_counter()
    roster = ROSTER[run]
    configs = [trainer_config(algo, 1000 * seed + off, options) for _, algo, off in roster]
    tabular = [k for k, (_, algo, _) in enumerate(roster) if SIMULATORS[algo] == BATCHED]
    bt = BatchedTrainer([configs[k] for k in tabular]) if tabular else None
    pyb = {k: Trainer(c) for k, c in enumerate(configs) if k not in tabular}
    views: list[Any] = []
    for k in range(len(roster)):
        if k in pyb:
            t = pyb[k]
            views.append(GridView(t) if t.learner_kind == "function" else t)
        else:
            assert bt is not None
            views.append(BatchedRobot(bt, tabular.index(k)))
    rows: list[dict[str, Any]] = []
    residuals: list[float] = []
    aggregate = AGGREGATIONS[options.method]
    respite = options.respite if len(roster) > 1 else options.iterations
    try:
        i = 0
        while i < options.iterations:
            stop = min(
                next_stop(i, options.iterations, respite, 0),
                min((e for e in options.eval_at if e > i), default=options.iterations),
            )
            for t in pyb.values():
                for _ in range(stop - i):
                    t.step()
            if bt is not None:
                bt.run(stop - i)
            i = stop
            if len(roster) > 1 and (i % options.respite == 0 or i == options.iterations):
                share(views, aggregate, residuals)
            if i in options.eval_at:
                rows += _evaluate(run, seed, options, roster, views, pyb, i)
        digests = {
            role: hashlib.sha256(
                (pyb[k].params if k in pyb else views[k].q_table.ravel()).tobytes()
            ).hexdigest()
            for k, (role, _, _) in enumerate(roster)
        }
    finally:
        for t in pyb.values():
            t.close()
    return {
        "rows": rows,
        "residuals": residuals,
        "digests": digests,
        "seconds": time.perf_counter() - t0,
    }


def _evaluate(
    run: str,
    seed: int,
    options: HeteroOptions,
    roster: tuple,
    views: list[Any],
    pyb: dict[int, Any],
    iteration: int,
) -> list[dict[str, Any]]:
    """Every robot's greedy score: the batched tables in one call, the others in pybullet."""
    batched = [k for k in range(len(roster)) if k not in pyb]
    measured: dict[int, dict[str, float]] = {}
    if batched:
        cfg = views[batched[0]].config.to_dict()
        evs = eval_many(
            cfg,
            [views[k].q_table for k in batched],
            [options.arena] * len(batched),
            options.eval_steps,
            options.episode_steps,
            EVAL_SEED + seed,
            BATCHED,
        )
        for k, ev in zip(batched, evs):
            measured[k] = {
                "score": ev["score"],
                "collisions_per_1000": ev["collisions_per_1000"],
                "progress": ev["progress"],
            }
    for k, t in pyb.items():
        function = t.learner_kind == "function"
        measured[k] = score_policy(
            t.config,
            seed,
            options,
            None if function else t.q_table.copy(),
            t.params if function else None,
        )
    return [
        {
            "seed": seed,
            "run": run,
            "role": role,
            "algo": algo,
            "sim": SIMULATORS[algo],
            "iteration": iteration,
            **measured[k],
        }
        for k, (role, algo, _) in enumerate(roster)
    ]
