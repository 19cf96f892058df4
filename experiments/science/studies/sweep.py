"""``dfrl sweep``: standalone learning under several hyper-parameter settings, several seeds
each, scored by the greedy policy's performance (:mod:`dfrl.robots.evaluation`).

A setting is a base :class:`~dfrl.robots.training.TrainerConfig` with some fields changed,
named by dotted paths into its JSON form (``learner.alpha``, ``learner.gamma``,
``learner.epsilon``, ``discretisation.grouping``, ``reward.alive_bonus``, ...). Factors are
swept one at a time around the base (``ofat``) or as a full grid (``grid``).

Each run trains for ``iterations`` with table snapshots every quarter, then evaluates the
greedy policy of the last ``stable_last`` snapshots in the training arena and in the held-out
arenas, with the same evaluation seed for every setting. Reported per setting (mean and 95% t
interval over seeds): forward progress, floor coverage and collisions per 1,000 steps (own
arena and held-out), the score, the Q-sum growth in the last quarter and the spread of the
score across the last snapshots (is learning saturated?).

Score: ``progress - 0.05 * collisions_per_1000``, averaged over the evaluation arenas (one
collision per 1,000 steps costs as much as 5% of top speed): a policy must drive ahead and
not collide; spinning scores 0.
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from dfrl.experiments.science.curves import late_growth
from dfrl.experiments.science.statistics import Interval, interval
from dfrl.experiments.science.studies.simulators import BATCHED, DEFAULT_SIM, check_sim
from dfrl.robots.evaluation import evaluate_snapshots
from dfrl.robots.training import TrainerConfig, train

#: Collisions per 1,000 steps that cost as much as full-speed progress (see module doc).
COLLISION_COST = 0.05
#: Offset of evaluation seeds from training seeds.
EVAL_SEED = 50_000


@dataclass(frozen=True)
class Setting:
    """A named set of changes to the base configuration."""

    name: str
    changes: tuple[tuple[str, Any], ...]


def set_path(d: dict[str, Any], path: str, value: Any) -> None:
    """Set ``d[a][b]...`` for ``path`` ``"a.b..."``.

    Raises
    ------
    KeyError
        A part of the path does not exist in the configuration.
    """
    keys = path.split(".")
    node = d
    for k in keys[:-1]:
        if not isinstance(node, dict) or k not in node:
            raise KeyError(f"{path}: no '{k}' in the configuration")
        node = node[k]
    if not isinstance(node, dict) or keys[-1] not in node:
        raise KeyError(f"{path}: no '{keys[-1]}' in the configuration")
    node[keys[-1]] = value


def settings(factors: dict[str, Sequence[Any]], mode: str = "ofat") -> list[Setting]:
    """The settings to run: the base first, then one per factor level (``ofat``) or one per
    combination (``grid``)."""
    if mode not in ("ofat", "grid"):
        raise ValueError(f"mode must be ofat or grid, got {mode!r}")
    out = [Setting("base", ())]
    if mode == "ofat":
        for path, levels in factors.items():
            for v in levels:
                out.append(Setting(f"{path}={_label(v)}", ((path, v),)))
    else:
        paths = list(factors)
        for combo in itertools.product(*(factors[p] for p in paths)):
            out.append(
                Setting(
                    ", ".join(f"{p}={_label(v)}" for p, v in zip(paths, combo)),
                    tuple(zip(paths, combo)),
                )
            )
    return out


def _label(v: Any) -> str:
    if isinstance(v, dict):
        return "{" + ",".join(f"{k}:{v[k]}" for k in sorted(v)) + "}"
    return str(v)


def setting_config(
    base: dict[str, Any], changes: tuple[tuple[str, Any], ...], seed: int
) -> TrainerConfig:
    """The configuration of one setting and seed."""
    d = copy.deepcopy(base)
    for path, value in changes:
        set_path(d, path, value)
    d["seed"] = seed
    return TrainerConfig.from_dict(d)


def run_one(
    base: dict[str, Any],
    changes: tuple[tuple[str, Any], ...],
    seed: int,
    arenas: tuple[str, ...],
    eval_steps: int,
    stable_last: int,
) -> dict[str, Any]:
    """Train one setting with one seed on pybullet and evaluate it (a process-pool job)."""
    cfg = setting_config(base, changes, seed)
    res = train(cfg, snapshot_every=max(1, cfg.iterations // 4))
    assert res.visits is not None and res.q_table is not None, "a tabular learner"
    last = dict(sorted(res.snapshots.items())[-stable_last:])
    rows = evaluate_snapshots(cfg, last, [cfg.arena, *arenas], eval_steps, EVAL_SEED + seed)
    return run_summary(cfg, rows, res.metrics["q_sum"], res.visits)


def run_summary(
    cfg: TrainerConfig, rows: Sequence[dict[str, Any]], q_sum: np.ndarray, visits: np.ndarray
) -> dict[str, Any]:
    """One run's measures from the evaluations of its last snapshots (``rows``: iteration,
    arena, progress, coverage, collisions_per_1000), its sum of Q-values per iteration and
    its visit counts (shape (n_states, n_actions))."""
    seed = cfg.seed
    last = sorted({int(r["iteration"]) for r in rows})
    final_it = max(last)
    score_by_it = {}
    for it in last:
        sel = [r for r in rows if r["iteration"] == it]
        score_by_it[it] = float(
            np.mean([r["progress"] - COLLISION_COST * r["collisions_per_1000"] for r in sel])
        )
    final = [r for r in rows if r["iteration"] == final_it]
    own = next(r for r in final if r["arena"] == cfg.arena)
    held = [r for r in final if r["arena"] != cfg.arena] or [own]
    visited = int((visits.sum(axis=1) > 0).sum())
    return {
        "seed": seed,
        "score": score_by_it[final_it],
        "score_spread": float(max(score_by_it.values()) - min(score_by_it.values())),
        "own_progress": own["progress"],
        "own_coverage": own["coverage"],
        "own_collisions_per_1000": own["collisions_per_1000"],
        "held_progress": float(np.mean([r["progress"] for r in held])),
        "held_collisions_per_1000": float(np.mean([r["collisions_per_1000"] for r in held])),
        "late_growth": late_growth(q_sum),
        "states_visited": visited,
        "states": int(visits.shape[0]),
    }


#: Per-setting summaries reported (mean and interval over seeds).
MEASURES = (
    "score",
    "own_progress",
    "own_coverage",
    "own_collisions_per_1000",
    "held_progress",
    "held_collisions_per_1000",
    "late_growth",
    "score_spread",
    "states_visited",
)


@dataclass(frozen=True)
class SettingResult:
    """All seeds of one setting."""

    setting: Setting
    runs: list[dict[str, Any]]

    def summary(self, measure: str) -> Interval:
        values = [r[measure] for r in self.runs if not math.isnan(float(r[measure]))]
        return interval(values) if values else Interval(float("nan"), float("nan"), 0)


def sweep(
    base: dict[str, Any],
    factors: dict[str, Sequence[Any]],
    seeds: Sequence[int],
    mode: str = "ofat",
    arenas: tuple[str, ...] = ("h1", "h2"),
    eval_steps: int = 2000,
    stable_last: int = 3,
    jobs: int = 2,
    sim: str = DEFAULT_SIM,
) -> list[SettingResult]:
    """Run every setting with every seed; results in setting order. On pybullet each run is
    a job of ``jobs`` processes; on the batched simulator (``sim``) the seeds of a setting
    train in one batch and its snapshots are evaluated in one call (:mod:`.sweep_batched`).

    Raises
    ------
    KeyError
        A factor names a configuration field that does not exist (checked before any run).
    ValueError
        An unknown simulator, or a setting the batched simulator cannot run (a learner
        without a table), checked before any run.
    """
    check_sim(sim)
    todo = settings(factors, mode)
    for s in todo:  # fail before the first run, not after an hour
        probe = copy.deepcopy(base)
        for path, value in s.changes:
            set_path(probe, path, value)
    if sim == BATCHED:
        from dfrl.experiments.science.studies.sweep_batched import sweep_batched

        runs = sweep_batched(
            base, [s.changes for s in todo], seeds, arenas, eval_steps, stable_last
        )
        return [SettingResult(s, r) for s, r in zip(todo, runs)]
    args = [
        (base, s.changes, seed, tuple(arenas), eval_steps, stable_last)
        for s in todo
        for seed in seeds
    ]
    if jobs <= 1:
        flat = [run_one(*a) for a in args]
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            flat = list(pool.map(run_one, *zip(*args)))
    n = len(seeds)
    return [SettingResult(s, flat[i * n : (i + 1) * n]) for i, s in enumerate(todo)]


def markdown_table(results: list[SettingResult]) -> str:
    """The sweep as a markdown table (mean ± 95% half width over seeds), best score first."""
    head = (
        "| setting | score | progress (own) | coverage (own) | collisions/1000 (own) | "
        "progress (held out) | collisions/1000 (held out) | Q-sum growth, last quarter | "
        "score spread, last snapshots | states visited |"
    )
    lines = [head, "|" + "---|" * 10]
    ranked = sorted(results, key=lambda r: -r.summary("score").mean)
    for r in ranked:
        cells = [r.setting.name] + [_cell(r.summary(m)) for m in MEASURES]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _cell(iv: Interval) -> str:
    if math.isnan(iv.mean):
        return "–"
    if math.isnan(iv.half):
        return f"{iv.mean:.2f}"
    return f"{iv.mean:.2f} ± {iv.half:.2f}"
