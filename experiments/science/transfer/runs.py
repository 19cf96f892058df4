"""Training runs of the transfer experiment, their statistics over seeds, :func:`run`."""

from __future__ import annotations

import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.arenas import load_arena
from dfrl.experiments.provenance import write_provenance
from dfrl.experiments.science.standalone import EVAL_SEED_OFFSET
from dfrl.experiments.science.transfer.model import (
    HEAD_STEPS,
    METRICS,
    Condition,
    RunResult,
    Stat,
    TransferConfig,
    TransferResult,
)
from dfrl.experiments.science.transfer.outputs import write_outputs
from dfrl.experiments.science.transfer.table import load_initial_table, trainer_config_for
from dfrl.robots.evaluation import PolicyKind, evaluate_policy
from dfrl.robots.training import Trainer, TrainerConfig


def run_one(
    trainer_config: TrainerConfig,
    condition: Condition | str,
    q0: np.ndarray | None,
    seed: int,
    eval_steps: int,
    every: int,
) -> RunResult:
    """Train one robot for ``trainer_config.iterations`` steps from ``q0`` (or zeros).

    Parameters
    ----------
    trainer_config : TrainerConfig
    condition : Condition
        Label only; the start table is ``q0``.
    q0 : np.ndarray, shape (n_states, n_actions), or None
        Initial table; ``None`` keeps the learner's own initialisation (zeros).
    seed : int
        Training seed; the evaluations use ``EVAL_SEED_OFFSET + seed``.
    eval_steps : int
        Greedy evaluation steps (0: no evaluation, NaN figures).
    every : int
        Curve sampling interval.
    """
    condition = Condition(condition)
    cfg = trainer_config.replace(seed=int(seed))
    n = cfg.iterations
    head, head10 = min(HEAD_STEPS, n), max(1, n // 10)
    collided = np.zeros(n, dtype=bool)
    points = list(range(every, n + 1, every))
    if not points or points[-1] != n:
        points.append(n)
    curve_c = np.zeros(len(points), dtype=np.int64)
    curve_r = np.zeros(len(points), dtype=np.float64)
    t0 = time.perf_counter()
    with Trainer(cfg) as trainer:
        if q0 is not None:
            trainer.set_q_table(q0)
        start = trainer.q_table.copy()
        k = 0
        for i in range(n):
            m = trainer.step()
            collided[i] = m.collided
            if m.iteration == points[k]:
                curve_c[k], curve_r[k] = m.collisions, m.cumulative_reward
                k += 1
        final = trainer.q_table.copy()
        cum_reward, respawns = trainer.cumulative_reward, trainer.respawns
    nan = float("nan")
    ev_c = ev_r = ev0_c = ev0_r = nan
    if eval_steps > 0:
        ev_seed = EVAL_SEED_OFFSET + int(seed)
        after = evaluate_policy(cfg, PolicyKind.GREEDY, eval_steps, ev_seed, q_table=final)
        before = evaluate_policy(cfg, PolicyKind.GREEDY, eval_steps, ev_seed, q_table=start)
        ev_c, ev_r = after.collisions_per_1000, after.mean_reward
        ev0_c, ev0_r = before.collisions_per_1000, before.mean_reward
    total = int(collided.sum())
    return RunResult(
        seed=int(seed),
        condition=condition.value,
        iterations=n,
        collisions=total,
        collisions_per_1000=1000.0 * total / n,
        head_steps=head,
        head_collisions_per_1000=1000.0 * int(collided[:head].sum()) / head,
        head10_steps=head10,
        head10_collisions_per_1000=1000.0 * int(collided[:head10].sum()) / head10,
        cumulative_reward=float(cum_reward),
        mean_reward=float(cum_reward) / n,
        eval_collisions_per_1000=ev_c,
        eval_mean_reward=ev_r,
        initial_eval_collisions_per_1000=ev0_c,
        initial_eval_mean_reward=ev0_r,
        respawns=int(respawns),
        wall_time=round(time.perf_counter() - t0, 3),
        curve_iteration=np.asarray(points, dtype=np.int64),
        curve_collisions=curve_c,
        curve_reward=curve_r,
    )


def run_job(args: tuple[dict[str, Any], str, np.ndarray | None, int, int, int]) -> RunResult:
    """:func:`run_one` on a picklable tuple (a worker process job)."""
    cfg_dict, condition, q0, seed, eval_steps, every = args
    return run_one(TrainerConfig.from_dict(cfg_dict), condition, q0, seed, eval_steps, every)


# -- aggregation -------------------------------------------------------------------------------
def aggregate(values: list[float]) -> Stat:
    """Mean and sample standard deviation (ddof 1; 0 for one value) of finite values."""
    arr = np.asarray([v for v in values if math.isfinite(v)], dtype=np.float64)
    if arr.size == 0:
        return Stat(float("nan"), float("nan"), 0)
    std = float(arr.std(ddof=1)) if arr.size > 1 else 0.0
    return Stat(float(arr.mean()), std, int(arr.size))


def summarise(runs: list[RunResult]) -> tuple[dict[str, dict[str, Stat]], dict[str, float]]:
    """Statistics per condition and metric, and the ratio of the means (init / zero)."""
    summary = {
        c.value: {
            m: aggregate([getattr(r, m) for r in runs if r.condition == c.value]) for m in METRICS
        }
        for c in Condition
    }
    ratio = {}
    for m in METRICS:
        a, b = summary["init"][m].mean, summary["zero"][m].mean
        ratio[m] = a / b if math.isfinite(a) and math.isfinite(b) and b != 0 else float("nan")
    return summary, ratio


# -- the experiment ----------------------------------------------------------------------------
def run(config: TransferConfig, output_dir: Path | None = None) -> TransferResult:
    """Train from the saved table and from zeros in ``config.arena``, for every seed.

    Writes, when ``output_dir`` is given: ``provenance.json`` (at the start:
    :mod:`dfrl.experiments.provenance`), ``config.json`` (this config, the trainer config and
    the table's description), ``runs.csv`` (one row per seed and condition), ``curves.csv``
    (cumulative collisions and reward every ``config.every`` steps), ``summary.json`` and
    ``transfer.png`` (mean cumulative collisions and reward over seeds; needs matplotlib).

    Raises
    ------
    ValueError
        A missing or bad table, an unknown arena or learner, or a table whose shape does not
        fit the trainer.
    """
    t0 = time.perf_counter()
    if output_dir is not None:
        write_provenance(output_dir)
    q, info, state = load_initial_table(config.init)
    tcfg = trainer_config_for(config, q, info, state)
    spec = load_arena(config.arena)  # ArenaError is a ValueError
    jobs = [
        (
            tcfg.to_dict(),
            cond.value,
            q if cond is Condition.INIT else None,
            seed,
            config.eval_steps,
            config.every,
        )
        for seed in config.seeds
        for cond in (Condition.INIT, Condition.ZERO)
    ]
    workers = max(1, min(config.jobs, len(jobs)))
    if workers == 1:
        runs = [run_job(j) for j in jobs]
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            runs = list(pool.map(run_job, jobs))
    summary, ratio = summarise(runs)
    out = Path(output_dir) if output_dir is not None else None
    result = TransferResult(
        config=config,
        trainer_config=tcfg,
        table=info,
        arena_name=spec.name,
        same_arena=info.arena is not None and info.arena.lower() == spec.name.lower(),
        runs=runs,
        summary=summary,
        ratio=ratio,
        wall_time=time.perf_counter() - t0,
        output_dir=out,
    )
    if out is not None:
        write_outputs(result, out)
    return result
