"""Greedy evaluations of a run's table history: ``evaluations.csv`` beside the curves.

A federated run's robot processes write ``tables/history/<robot>_it<N>.npy`` at every share; a
standalone run keeps ``snapshots.npz`` (``it<N>`` keys). :func:`evaluate_tables` measures the
greedy policy of chosen tables in the robot's own arena and in held-out arenas
(:func:`dfrl.robots.evaluation.evaluate_policy`, many short seeded episodes, the same seed for
every table so that the curves compare tables, not start poses). Identical tables (after an
``average`` share every robot holds the same one) are evaluated once per arena.
:func:`eval_many` measures many tables at once, on the batched simulator in one compiled call.

Score of one evaluation: ``progress - COLLISION_COST * collisions_per_1000``
(:mod:`dfrl.experiments.science.studies.sweep`): driving ahead without colliding scores near 1,
spinning in place 0.
"""

from __future__ import annotations

import csv
import hashlib
import re
from collections.abc import Iterable, Sequence
from concurrent.futures import Executor
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.arenas import load_arena
from dfrl.experiments.science.studies.simulators import PYBULLET, check_sim
from dfrl.experiments.science.studies.sweep import COLLISION_COST
from dfrl.robots.evaluation import EvalResult, PolicyKind, evaluate_policy
from dfrl.robots.training import TrainerConfig

#: Columns of ``evaluations.csv``.
FIELDS: tuple[str, ...] = (
    "robot",
    "iteration",
    "arena",
    "role",
    "steps",
    "collisions_per_1000",
    "progress",
    "coverage",
    "mean_reward",
    "score",
)

_HIST = re.compile(r"^(?P<robot>.+)_it(?P<it>\d+)\.npy$")


def history_tables(results_dir: Path) -> dict[str, dict[int, Path]]:
    """``tables/history`` of a federated results folder: robot -> iteration -> file."""
    out: dict[str, dict[int, Path]] = {}
    d = Path(results_dir) / "tables" / "history"
    for p in sorted(d.glob("*.npy")) if d.is_dir() else []:
        m = _HIST.match(p.name)
        if m:
            out.setdefault(m["robot"], {})[int(m["it"])] = p
    return out


def pick(iterations: Iterable[int], total: int, points: int) -> list[int]:
    """The ``points`` iterations nearest to ``total * k / points`` (k = 1..points)."""
    its = sorted(set(iterations))
    if not its:
        return []
    out = []
    for k in range(1, points + 1):
        target = total * k / points
        out.append(min(its, key=lambda i: (abs(i - target), -i)))
    return sorted(set(out))


def digest(q: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(q, dtype=np.float64).tobytes()).hexdigest()


def measured(r: EvalResult) -> dict[str, float]:
    """An evaluation's numbers as the rows keep them, with its score."""
    return {
        "steps": r.steps,
        "collisions_per_1000": r.collisions_per_1000,
        "progress": r.progress,
        "coverage": r.coverage,
        "mean_reward": r.mean_reward,
        "score": r.progress - COLLISION_COST * r.collisions_per_1000,
    }


def eval_job(
    cfg_dict: dict[str, Any], q: np.ndarray, arena: str, steps: int, episode_steps: int, seed: int
) -> dict[str, float]:
    """One greedy evaluation in pybullet (a process-pool job)."""
    cfg = TrainerConfig.from_dict(cfg_dict).replace(arena=arena)
    r = evaluate_policy(cfg, PolicyKind.GREEDY, steps, seed, q_table=q, episode_steps=episode_steps)
    return measured(r)


def eval_many(
    cfg_dict: dict[str, Any],
    tables: Sequence[np.ndarray],
    arenas: Sequence[str],
    steps: int,
    episode_steps: int,
    seeds: Sequence[int] | int,
    sim: str = PYBULLET,
) -> list[dict[str, float]]:
    """The greedy evaluation of ``tables[j]`` in ``arenas[j]`` with seed ``seeds[j]`` (or one
    seed for all), for every ``j``, as :func:`eval_job` measures it: on the batched simulator
    in one compiled call (:func:`dfrl.robots.batched.evaluation.evaluate_greedy`), on pybullet
    one after the other.

    Raises
    ------
    ValueError
        Lengths that differ, a table of the wrong shape or an unknown simulator.
    """
    check_sim(sim)
    seed_list = [seeds] * len(tables) if isinstance(seeds, (int, np.integer)) else list(seeds)
    if not len(tables) == len(arenas) == len(seed_list):
        raise ValueError(
            f"{len(tables)} tables, {len(arenas)} arenas and {len(seed_list)} "
            f"seeds: one of each per evaluation"
        )
    if sim == PYBULLET:
        return [
            eval_job(cfg_dict, q, a, steps, episode_steps, int(s))
            for q, a, s in zip(tables, arenas, seed_list)
        ]
    from dfrl.robots.batched.evaluation import evaluate_greedy

    cfg = TrainerConfig.from_dict(cfg_dict)
    # each arena parsed once: the batched world would parse a name once per evaluation
    specs = {a: load_arena(a) for a in dict.fromkeys(arenas)}
    return [
        measured(r)
        for r in evaluate_greedy(
            cfg, tables, [specs[a] for a in arenas], steps, seed_list, episode_steps
        )
    ]


class Evaluator:
    """Schedules greedy evaluations on an executor; identical (table, arena) pairs once.

    Parameters
    ----------
    pool : Executor
    cfg_dict : dict
        Trainer configuration of the tables (discretisation, actions, reward, sim).
    steps, episode_steps, seed : int
        As in :func:`dfrl.robots.evaluation.evaluate_policy`.
    """

    def __init__(
        self, pool: Executor, cfg_dict: dict[str, Any], steps: int, episode_steps: int, seed: int
    ) -> None:
        self.pool, self.cfg, self.steps = pool, cfg_dict, steps
        self.episode_steps, self.seed = episode_steps, seed
        self._futures: dict[tuple[str, str], Any] = {}

    def submit(self, q: np.ndarray, arena: str) -> Any:
        key = (digest(q), arena)
        if key not in self._futures:
            self._futures[key] = self.pool.submit(
                eval_job, self.cfg, q, arena, self.steps, self.episode_steps, self.seed
            )
        return self._futures[key]


class PendingRows:
    """Rows of one ``evaluations.csv`` whose numbers are still being computed."""

    def __init__(self) -> None:
        self.rows: list[tuple[dict[str, Any], Any]] = []

    def add(
        self,
        evaluator: Evaluator,
        robot: str,
        iteration: int,
        q: np.ndarray,
        own: str,
        held_out: Sequence[str],
    ) -> None:
        for arena, role in [(own, "own")] + [(a, "held_out") for a in held_out]:
            self.rows.append(
                (
                    {"robot": robot, "iteration": iteration, "arena": arena, "role": role},
                    evaluator.submit(q, arena),
                )
            )

    def write(self, path: Path) -> list[dict[str, Any]]:
        """Wait for every number and write the CSV; return the rows."""
        rows = [{**head, **fut.result()} for head, fut in self.rows]
        write_rows(path, rows)
        return rows


def write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def read_rows(path: Path) -> list[dict[str, Any]]:
    """``evaluations.csv`` back, numbers as numbers."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        r["iteration"] = int(r["iteration"])
        r["steps"] = int(r["steps"])
        for k in FIELDS[5:]:
            r[k] = float(r[k])
    return rows
