"""Transfer experiment: does a saved Q-table help a robot learn in an arena it has never seen?

For every seed, two robots train in the same arena, from the same seed, for the same budget:

* ``init``: its Q-table starts as a copy of the saved table (standalone or federated);
* ``zero``: its Q-table starts at zero (the usual start).

Both use the same learner settings (default :class:`dfrl.robots.training.TrainerConfig` values,
with the algorithm, sensor grouping, levels and action set read from the table's sidecar),
so the only difference is the initial table. Reported per run and aggregated over seeds:

* collisions per 1,000 training steps, overall, over the first ``min(1000, N)`` steps and over
  the first 10% of the steps (where a head start shows);
* final cumulative reward and mean reward per step;
* a greedy evaluation of the final table (collisions per 1,000 steps and mean reward per
  step, :func:`dfrl.robots.evaluation.evaluate_policy`), and one of the initial table before any
  training (for ``zero`` that is a uniformly random policy: all ties), from the same poses.

Usage::

    from dfrl.experiments.science.transfer import TransferConfig, run
    result = run(TransferConfig(init="results/r1/q_table.npy", arena="my_arena.json",
                                iterations=3000, seeds=(1, 2, 3, 4, 5)), Path("results/transfer"))
    result.summary["init"]["collisions_per_1000"].mean, result.ratio["collisions_per_1000"]

The paper's transfer claim across seeds and arenas (federated source against a matched
standalone source of every source arena; collisions and greedy score while learning, and the
censored time to a threshold lifted above every start; learning phases seeded per source seed;
paired intervals, Holm, verdicts, no verdict from a degenerate interval) is
``dfrl transfer-study``: :mod:`.study` runs it, :mod:`.claims` judges it and writes its files.
"""

from __future__ import annotations

from dfrl.experiments.science.transfer.model import (
    HEAD_STEPS,
    METRICS,
    Condition,
    RunResult,
    Stat,
    TableInfo,
    TransferConfig,
    TransferResult,
)
from dfrl.experiments.science.transfer.outputs import plot_transfer, write_outputs
from dfrl.experiments.science.transfer.runs import aggregate, run, run_one, summarise
from dfrl.experiments.science.transfer.table import load_initial_table, trainer_config_for

__all__ = [
    "Condition",
    "HEAD_STEPS",
    "METRICS",
    "RunResult",
    "Stat",
    "TableInfo",
    "TransferConfig",
    "TransferResult",
    "aggregate",
    "load_initial_table",
    "run",
    "run_one",
    "summarise",
    "trainer_config_for",
    "write_outputs",
    "plot_transfer",
]
