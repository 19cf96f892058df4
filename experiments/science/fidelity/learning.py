"""The decisive check: do tables learnt in the batched simulator do as well in pybullet?

For each arena and each of ``seeds`` seeds, a block of ``tables`` tables is learnt in each
simulator (training seeds ``1000 * seed + m``, the same in both), every table is evaluated in
pybullet with the greedy policy (evaluation seed ``EVAL_SEED + 1000 * seed + m``, the same for
the two tables of a pair), and the seed's value is the mean score of its batched block minus the
mean score of its pybullet block. The check holds when the 95% t interval of the mean over seeds
lies within ``(-margin, +margin)`` (an equivalence test: each of its one-sided 2.5% tests
rejects a difference of ``margin`` or more). A block of tables per seed is needed because one
learnt table's score varies by 0.2-0.3 between seeds at 10,000 iterations: with one table per
seed, 10 seeds give an interval of about +-0.2.
"""

from __future__ import annotations

from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np

from dfrl.experiments.science.statistics import interval
from dfrl.robots.batched.evaluation import evaluate_greedy
from dfrl.robots.batched.training import BatchedTrainer
from dfrl.robots.evaluation import PolicyKind, evaluate_policy
from dfrl.robots.training import TrainerConfig, train

#: base of the evaluation seeds
EVAL_SEED: int = 50_000
#: the score's price of one collision per 1,000 steps, as the studies' (robots/README.md)
COLLISION_COST: float = 0.05


@dataclass(frozen=True)
class LearningCheck:
    """Budget of the decisive check."""

    seeds: int = 10
    tables: int = 15
    iterations: int = 10_000
    eval_steps: int = 2000
    episode_steps: int = 200
    margin: float = 0.05

    def check(self) -> None:
        """Raises ValueError for a budget that cannot give an interval."""
        if self.seeds < 2 or self.tables < 1 or self.iterations < 1:
            raise ValueError("the learning check needs seeds >= 2, tables >= 1, iterations >= 1")
        if self.eval_steps < 1 or self.episode_steps < 1 or self.margin <= 0:
            raise ValueError("eval_steps, episode_steps and margin must be positive")


def _score(progress: float, collisions_per_1000: float) -> float:
    return progress - COLLISION_COST * collisions_per_1000


def train_job(cfg: dict[str, Any]) -> np.ndarray:
    """One table learnt in pybullet (a pool job)."""
    result = train(TrainerConfig.from_dict(cfg))
    assert result.q_table is not None, "a tabular learner"
    return result.q_table


def eval_job(
    cfg: dict[str, Any], table: np.ndarray, steps: int, episode_steps: int, seed: int
) -> float:
    """The pybullet score of a table's greedy policy (a pool job)."""
    r = evaluate_policy(
        TrainerConfig.from_dict(cfg),
        PolicyKind.GREEDY,
        steps,
        seed,
        q_table=table,
        episode_steps=episode_steps,
    )
    return _score(r.progress, r.collisions_per_1000)


def check_learning(
    base: TrainerConfig, arena: str, budget: LearningCheck, pool: Executor
) -> dict[str, Any]:
    """Run the decisive check in one arena (see the module doc); pybullet work on ``pool``."""
    budget.check()
    keys = [(s, m) for s in range(1, budget.seeds + 1) for m in range(budget.tables)]
    configs = [
        base.replace(arena=arena, seed=1000 * s + m, iterations=budget.iterations) for s, m in keys
    ]
    eval_seeds = [EVAL_SEED + 1000 * s + m for s, m in keys]
    pb_futures = [pool.submit(train_job, c.to_dict()) for c in configs]
    batched = BatchedTrainer(configs)
    batched.run(budget.iterations)
    b_tables = [batched.q[k].copy() for k in range(len(keys))]
    in_batched = [
        _score(r.progress, r.collisions_per_1000)
        for r in evaluate_greedy(
            configs[0],
            b_tables,
            [arena] * len(keys),
            budget.eval_steps,
            eval_seeds,
            budget.episode_steps,
        )
    ]
    cfg = configs[0].to_dict()
    b_scores = [
        pool.submit(eval_job, cfg, t, budget.eval_steps, budget.episode_steps, e)
        for t, e in zip(b_tables, eval_seeds)
    ]
    pb_scores = [
        pool.submit(eval_job, cfg, f.result(), budget.eval_steps, budget.episode_steps, e)
        for f, e in zip(pb_futures, eval_seeds)
    ]
    b = np.array([f.result() for f in b_scores]).reshape(budget.seeds, budget.tables)
    pb = np.array([f.result() for f in pb_scores]).reshape(budget.seeds, budget.tables)
    diff = interval((b.mean(axis=1) - pb.mean(axis=1)).tolist())
    return {
        "arena": arena,
        "seeds": budget.seeds,
        "tables_per_seed": budget.tables,
        "iterations": budget.iterations,
        "margin": budget.margin,
        "batched_learnt_in_pybullet": float(b.mean()),
        "pybullet_learnt_in_pybullet": float(pb.mean()),
        "batched_learnt_in_batched": float(np.mean(in_batched)),
        "table_sd": {"batched": float(b.std(ddof=1)), "pybullet": float(pb.std(ddof=1))},
        "difference": diff.mean,
        "half_width": diff.half,
        "interval": [diff.low, diff.high],
        "per_seed": (b.mean(axis=1) - pb.mean(axis=1)).tolist(),
        "holds": bool(-budget.margin < diff.low and diff.high < budget.margin),
    }
