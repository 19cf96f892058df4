"""``dfrl transfer-study`` on the batched simulator: each stage of the study in a few compiled
calls instead of a process pool of pybullet robots.

* :func:`reference_levels`: every reference run of every unseen arena in one
  :class:`~dfrl.robots.batched.training.BatchedTrainer`, all their tables evaluated in one
  call at each level point;
* :func:`alone`: one robot trained alone (the standalone sources);
* :func:`learning_phases`: every learning phase (source x unseen arena x target seed) in one
  trainer, stepped to each point of the grid, every learning table evaluated there in one call.

The robots of a batch do not interact (each has its own arena and random streams, seeded as a
:class:`~dfrl.robots.training.Trainer` would seed them), so a phase learns and scores the same
in any batch (tested). Seeds, grid and measures are those of :mod:`.study` and
:mod:`.thresholds`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from dfrl.experiments.science.studies.history import eval_many
from dfrl.experiments.science.studies.simulators import BATCHED
from dfrl.experiments.science.transfer.thresholds import (
    REFERENCE_EVAL_OFFSET,
    REFERENCE_SEED_BASE,
    level_points,
)
from dfrl.robots.batched.training import BatchedTrainer
from dfrl.robots.training import TrainerConfig

if TYPE_CHECKING:
    from dfrl.experiments.science.transfer.study import StudyOptions


def reference_levels(
    jobs: Sequence[tuple[str, int]], iterations: int, eval_steps: int, episode_steps: int
) -> list[float]:
    """The level of reference run ``k`` in ``arena`` for every ``(arena, k)`` of ``jobs``, as
    :func:`.thresholds.reference_job` measures it."""
    if not jobs:
        return []
    bt = BatchedTrainer(
        [
            TrainerConfig(arena=a, seed=REFERENCE_SEED_BASE + k, iterations=iterations)
            for a, k in jobs
        ]
    )
    arenas = [a for a, _ in jobs]
    seeds = [REFERENCE_SEED_BASE + REFERENCE_EVAL_OFFSET + k for _, k in jobs]
    scores: list[list[float]] = [[] for _ in jobs]
    for point in level_points(iterations):
        bt.run(point - bt.iteration)
        evs = eval_many(
            TrainerConfig().to_dict(), list(bt.q), arenas, eval_steps, episode_steps, seeds, BATCHED
        )
        for mine, ev in zip(scores, evs):
            mine.append(float(ev["score"]))
    return [float(np.mean(s)) for s in scores]


def alone(config: TrainerConfig) -> np.ndarray:
    """The table of one robot trained ``config.iterations`` steps alone."""
    bt = BatchedTrainer([config])
    bt.run(config.iterations)
    return bt.q[0].copy()


def learning_phases(
    sources: Sequence[tuple[str, int, np.ndarray]], opts: StudyOptions
) -> list[dict[str, Any]]:
    """Every learning phase of ``sources`` ((condition, source seed, table)) in every unseen
    arena and target seed, in that order: the rows of :func:`.study.target_job`."""
    from dfrl.experiments.science.transfer.study import pair_seed, phase_row, phase_seeds

    phases = [
        (c, s, q, a, t) for c, s, q in sources for a in opts.targets for t in opts.target_seeds
    ]
    if not phases:
        return []
    seeds = [phase_seeds(pair_seed(c, s, opts), t) for c, s, _, _, t in phases]
    bt = BatchedTrainer(
        [
            TrainerConfig(arena=a, seed=train, iterations=opts.learn)
            for (_, _, _, a, _), (train, _) in zip(phases, seeds)
        ]
    )
    for k, (_, _, q, _, _) in enumerate(phases):
        bt.set_table(k, q)
    arenas = [a for _, _, _, a, _ in phases]
    ev_seeds = [ev for _, ev in seeds]
    ev_cfg = TrainerConfig().to_dict()
    scores: list[list[tuple[int, float]]] = [[] for _ in phases]
    collisions: list[list[tuple[int, int]]] = [[] for _ in phases]
    for g in opts.grid():
        bt.run(g - bt.iteration)
        hits = bt.collisions
        evs = eval_many(
            ev_cfg, list(bt.q), arenas, opts.eval_steps, opts.episode_steps, ev_seeds, BATCHED
        )
        for k, ev in enumerate(evs):
            collisions[k].append((g, int(hits[k])))
            scores[k].append((g, float(ev["score"])))
    return [
        phase_row(c, s, a, t, opts, scores[k], collisions[k])
        for k, (c, s, _, a, t) in enumerate(phases)
    ]
