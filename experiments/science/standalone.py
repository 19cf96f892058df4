"""Standalone robot runs (no federation): baselines and the greedy-vs-random evaluation.

Used by ``dfrl baselines``, ``dfrl eval`` and the paper reproduction. Library code: the
functions return numbers and paths; the CLI prints them.
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from dfrl.experiments.science.studies import history
from dfrl.robots.evaluation import PolicyKind, evaluate_policy
from dfrl.robots.state import DiscretisationConfig
from dfrl.robots.tables import load_table
from dfrl.robots.training import TrainerConfig, train

#: Offset between a training seed and the seed of its evaluation episodes (so that the
#: evaluation does not replay the training's starts).
EVAL_SEED_OFFSET: int = 10_000

#: Called with (algo, arena, wall seconds) when a baseline run ends.
RunDone = Callable[[str, str, float], None]


def baseline_job(cfg_dict: dict[str, Any], out: str) -> tuple[str, str, float]:
    """Train one standalone robot into ``out`` (a worker process job)."""
    cfg = TrainerConfig.from_dict(cfg_dict)
    result = train(cfg, out)
    return cfg.algo, cfg.arena, result.wall_time


def run_jobs(
    jobs: list[tuple[TrainerConfig, Path]], workers: int, on_done: RunDone | None = None
) -> None:
    """Train every ``(config, folder)`` on ``workers`` processes, in order of submission."""
    if not jobs:
        return
    with ProcessPoolExecutor(max_workers=max(1, workers)) as pool:
        futures = [pool.submit(baseline_job, c.to_dict(), str(o)) for c, o in jobs]
        for fut in futures:
            algo, arena, wall = fut.result()
            if on_done is not None:
                on_done(algo, arena, wall)


def evaluated_job(
    cfg_dict: dict[str, Any],
    out: str,
    points: int,
    held_out: list[str],
    steps: int,
    episode_steps: int,
    eval_seed: int,
) -> str:
    """Train one standalone robot into ``out`` with ``points`` snapshots, then evaluate each
    snapshot's greedy policy in its own arena and the last one's in the held-out arenas too
    (``out/evaluations.csv``, :mod:`dfrl.experiments.science.studies.history`); a worker
    process job. Returns ``out``."""
    cfg = TrainerConfig.from_dict(cfg_dict)
    res = train(cfg, out, snapshot_every=max(1, cfg.iterations // max(1, points)))
    rows = []
    last = max(res.snapshots, default=None)
    for it, q in sorted(res.snapshots.items()):
        elsewhere = held_out if it == last else []  # held-out arenas at the end only
        for arena, role in [(cfg.arena, "own")] + [(a, "held_out") for a in elsewhere]:
            rows.append(
                {
                    "robot": cfg.arena,
                    "iteration": it,
                    "arena": arena,
                    "role": role,
                    **history.eval_job(cfg_dict, q, arena, steps, episode_steps, eval_seed),
                }
            )
    history.write_rows(Path(out) / "evaluations.csv", rows)
    return out


# -- evaluation ------------------------------------------------------------------------------
@dataclass(frozen=True)
class EvalSummary:
    """Greedy learned policy vs uniformly random policy, collisions per 1,000 steps."""

    arena: str
    algo: str
    iterations: int
    seeds: list[int]
    eval_steps: int
    table: str | None
    runs: list[dict[str, Any]]
    greedy_collisions_per_1000: float
    random_collisions_per_1000: float
    reduction: float

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def eval_job(
    cfg_dict: dict[str, Any], seed: int, steps: int, table_path: str | None
) -> dict[str, Any]:
    """Train with ``seed`` (or load ``table_path``), then evaluate greedy and random."""
    cfg = TrainerConfig.from_dict(cfg_dict).replace(seed=seed)
    t0 = time.perf_counter()
    q = train(cfg).q_table if table_path is None else load_table(table_path).q
    train_s = time.perf_counter() - t0
    eval_seed = EVAL_SEED_OFFSET + seed
    greedy = evaluate_policy(cfg, PolicyKind.GREEDY, steps, eval_seed, q_table=q)
    rand = evaluate_policy(cfg, PolicyKind.RANDOM, steps, eval_seed)
    return {
        "seed": seed,
        "train_s": round(train_s, 2),
        "greedy": greedy.__dict__,
        "random": rand.__dict__,
    }


def with_table_discretisation(cfg: TrainerConfig, table: str) -> TrainerConfig:
    """``cfg`` with the discretisation recorded in ``table``'s sidecar.

    Raises
    ------
    ValueError, OSError, KeyError
        The table or its sidecar cannot be read.
    """
    state = load_table(table).meta.state
    return cfg.replace(discretisation=DiscretisationConfig(state["grouping"], state["levels"]))


def evaluate(
    cfg: TrainerConfig, seeds: list[int], steps: int, table: str | None = None, jobs: int = 1
) -> EvalSummary:
    """Greedy vs random over ``seeds`` (one training run per seed unless ``table`` is given).

    Raises
    ------
    ValueError, OSError
        A bad table, arena or configuration.
    """
    workers = max(1, min(jobs, len(seeds)))
    n = len(seeds)
    if workers == 1:
        rows = [eval_job(cfg.to_dict(), s, steps, table) for s in seeds]
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            rows = list(pool.map(eval_job, [cfg.to_dict()] * n, seeds, [steps] * n, [table] * n))
    total = steps * len(rows)
    g_rate = 1000.0 * sum(r["greedy"]["collisions"] for r in rows) / total
    r_rate = 1000.0 * sum(r["random"]["collisions"] for r in rows) / total
    reduction = 1.0 - g_rate / r_rate if r_rate > 0 else float("nan")
    return EvalSummary(
        cfg.arena,
        cfg.algo,
        cfg.iterations,
        list(seeds),
        steps,
        table,
        rows,
        g_rate,
        r_rate,
        reduction,
    )
