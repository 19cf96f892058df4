"""``dfrl sweep`` on the batched simulator: every seed of a setting in one
:class:`~dfrl.robots.batched.training.BatchedTrainer`, snapshots every quarter as
:func:`dfrl.robots.training.train` keeps them, and every snapshot, seed and evaluation arena
of the setting in one compiled evaluation call; the measures of :func:`.sweep.run_summary`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from dfrl.experiments.science.studies.history import eval_many
from dfrl.experiments.science.studies.simulators import BATCHED
from dfrl.experiments.science.studies.sweep import EVAL_SEED, run_summary, setting_config
from dfrl.robots.batched.training import BatchedTrainer, shared_env
from dfrl.robots.training import TrainerConfig

#: Episodes of the snapshots' evaluations (:func:`dfrl.robots.evaluation.evaluate_snapshots`).
EPISODE_STEPS = 250


def snapshot_points(iterations: int) -> list[int]:
    """Where :func:`dfrl.robots.training.train` keeps a snapshot with ``snapshot_every`` a
    quarter of ``iterations``: every quarter and the last iteration."""
    every = max(1, iterations // 4)
    return sorted(set(range(every, iterations + 1, every)) | {iterations})


def train_setting(
    configs: Sequence[TrainerConfig], stable_last: int
) -> tuple[dict[int, np.ndarray], np.ndarray, np.ndarray]:
    """Train one robot per config (same iterations) in one batch: the last ``stable_last``
    snapshots (iteration -> tables, shape (robots, n_states, n_actions)), the sums of
    Q-values per iteration (robots, iterations) and the final visit counts."""
    iterations = configs[0].iterations
    bt = BatchedTrainer(configs)
    q_sum = np.zeros((bt.n, iterations))
    keep = snapshot_points(iterations)[-stable_last:]
    snaps: dict[int, np.ndarray] = {}
    for point in snapshot_points(iterations):
        start = bt.iteration
        rec = bt.run(point - start, record=True)
        assert rec is not None
        q_sum[:, start:point] = rec.q_sum
        if point in keep:
            snaps[point] = bt.q.copy()
    return snaps, q_sum, bt.visits.copy()


def sweep_batched(
    base: dict[str, Any],
    settings: Sequence[tuple[tuple[str, Any], ...]],
    seeds: Sequence[int],
    arenas: tuple[str, ...],
    eval_steps: int,
    stable_last: int,
) -> list[list[dict[str, Any]]]:
    """The runs of every setting (its changes to ``base``), one per seed, in order.

    Raises
    ------
    BatchError
        A setting the batched simulator cannot run (checked for every setting before any
        training).
    """
    configs = [[setting_config(base, changes, s) for s in seeds] for changes in settings]
    for changes, cfgs in zip(settings, configs):
        try:
            shared_env(cfgs)
        except ValueError as exc:
            name = ", ".join(f"{p}={v}" for p, v in changes) or "base"
            raise type(exc)(f"setting {name}: {exc}") from exc
    return [_setting(cfgs, arenas, eval_steps, stable_last) for cfgs in configs]


def _setting(
    cfgs: list[TrainerConfig], arenas: tuple[str, ...], eval_steps: int, stable_last: int
) -> list[dict[str, Any]]:
    snaps, q_sum, visits = train_setting(cfgs, stable_last)
    jobs = [
        (k, it, a) for k, c in enumerate(cfgs) for it in sorted(snaps) for a in (c.arena, *arenas)
    ]
    evs = eval_many(
        cfgs[0].to_dict(),
        [snaps[it][k] for k, it, _ in jobs],
        [a for _, _, a in jobs],
        eval_steps,
        EPISODE_STEPS,
        [EVAL_SEED + cfgs[k].seed for k, _, _ in jobs],
        BATCHED,
    )
    rows: list[list[dict[str, Any]]] = [[] for _ in cfgs]
    for (k, it, a), ev in zip(jobs, evs):
        rows[k].append({"iteration": it, "arena": a, **ev})
    return [run_summary(c, rows[k], q_sum[k], visits[k]) for k, c in enumerate(cfgs)]
