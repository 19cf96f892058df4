"""Reproduce the paper's figures: four federated runs, the standalone baselines, ``report.md``.

Runs the four federated combinations (Q-learning / SARSA x average / max, five robots in
R1..R5, ``experiments/configs/paper_*.json``) and the standalone baselines (each arena alone,
same seeds and budget), gathers the eight federated figures (sum of Q-values and cumulative
reward per robot, per combination) and draws the two baseline figures (R1 vs R4, as in the
paper), and writes ``report.md`` (:mod:`dfrl.experiments.report.paper`).
"""
from __future__ import annotations

import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.config import ExperimentConfig, resolve_config
from dfrl.experiments.launcher import run
from dfrl.experiments.report.paper import write_report
from dfrl.experiments.report.stats import (ALGO_NAMES, COMBOS, CombinationRun, StandaloneRuns,
                                           stats_of)
from dfrl.experiments.results.metrics import read_metrics
from dfrl.experiments.results.rounds import count_equal, read_rounds_csv
from dfrl.experiments.standalone import run_baselines


@dataclass(frozen=True)
class Reproduction:
    """What :func:`reproduce_paper` produced; ``ok``: every federated run succeeded."""

    report: Path
    runs: dict[tuple[str, str], CombinationRun]
    standalone: dict[str, StandaloneRuns]
    total_s: float
    ok: bool


def federated_run(algo: str, method: str, out: Path, changes: dict[str, Any],
                  skip_existing: bool, progress: TextIO | None) -> CombinationRun:
    """Run (or reuse) one combination into ``OUT/NAME``; copy its figures to ``OUT/figures``."""
    cfg = ExperimentConfig.load(resolve_config(f"paper_{algo}_{method}"))
    cfg = cfg.replace(**changes) if changes else cfg
    d = out / cfg.name
    t1 = time.monotonic()
    ok = True
    if not (skip_existing and (d / "summary.md").is_file() and (d / "metrics.csv").is_file()):
        if progress is not None:
            print(f"== {cfg.name}: {len(cfg.robots)} robots, {cfg.iterations} iterations, "
                  f"{cfg.rounds} rounds", file=progress)
        ok = run(cfg, d, progress=progress).ok
    wall = time.monotonic() - t1
    arenas = {r.id: r.arena for r in cfg.robots}
    curves = read_metrics(d / "metrics.csv")
    rows = read_rounds_csv(d / "rounds.csv")
    for name in ("q_sum", "cumulative_reward"):
        if (d / f"{name}.png").is_file():
            shutil.copy(d / f"{name}.png", out / "figures" / f"{algo}_{method}_{name}.png")
    return CombinationRun(cfg, curves, arenas, wall, ok, len(rows), count_equal(rows),
                          stats_of(curves, arenas))


def reproduce_paper(out: Path, iterations: int | None = None, respite: int | None = None,
                    seed: int | None = None, baseline_iterations: int | None = None,
                    skip_existing: bool = False,
                    progress: TextIO | None = sys.stderr) -> Reproduction:
    """Run everything and write ``OUT/report.md`` (progress lines to ``progress``).

    Raises
    ------
    ExperimentError
        A federated run could not be started.
    """
    from dfrl.robots.plots import plot_learning_curves
    from dfrl.robots.training import read_metrics_csv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures = out / "figures"
    figures.mkdir(exist_ok=True)
    t0 = time.monotonic()
    changes = {k: v for k, v in (("iterations", iterations), ("respite", respite), ("seed", seed))
               if v is not None}
    runs = {(algo, method): federated_run(algo, method, out, changes, skip_existing, progress)
            for algo, method in COMBOS}
    cfg0 = runs[COMBOS[0]].cfg
    arena_seeds = {r.arena: cfg0.robot_seed(r) for r in cfg0.robots}
    arena_list = [r.arena for r in cfg0.robots]
    b_iters = baseline_iterations or cfg0.iterations
    t1 = time.monotonic()
    dirs = run_baselines(out, arena_list, arena_seeds, b_iters, skip_existing, progress=progress)
    baseline_wall = time.monotonic() - t1
    standalone = {}
    for algo in ("qlearning", "sarsa"):
        curves = {a: read_metrics_csv(dirs[(algo, a)] / "metrics.csv") for a in arena_list}
        standalone[algo] = StandaloneRuns(curves, stats_of(curves, {a: a for a in arena_list}))
        shown = {a.upper(): curves[a] for a in ("r1", "r4") if a in curves}
        plot_learning_curves(shown, figures / f"baseline_{algo}.png",
                             f"Standalone {ALGO_NAMES[algo]}, {b_iters} iterations (R1 vs R4)")
    total = time.monotonic() - t0
    report = write_report(out, runs, standalone, total, baseline_wall, b_iters)
    return Reproduction(report, runs, standalone, total, all(r.ok for r in runs.values()))
