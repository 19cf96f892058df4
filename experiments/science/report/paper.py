"""``report.md`` of ``dfrl paper``: figures with bands, the paper's observations as tests with
intervals and verdicts against negative controls that cannot have learned
(:mod:`dfrl.experiments.science.report.observations`), the off-policy reference."""
from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.provenance import describe, read_provenance
from dfrl.experiments.science.report.bands import plot_groups
from dfrl.experiments.science.report.measures import SeedRun, final_score, mean_q
from dfrl.experiments.science.report.observations import paper_tests
from dfrl.experiments.science.report.verdict_text import summary_markdown, tests_markdown
from dfrl.experiments.science.curves import late_growth
from dfrl.experiments.science.statistics import interval


def _iv(values: list[float]) -> str:
    vals = [v for v in values if v == v]
    return str(interval(vals)) if vals else "n/a"


def seeds_words(seeds: Sequence[int]) -> str:
    """``Seeds 1, 2, 3 (3)``; a run of consecutive seeds as ``Seeds 1..5 (5)``."""
    ss = list(seeds)
    if len(ss) > 2 and ss == list(range(ss[0], ss[0] + len(ss))):
        return f"Seeds {ss[0]}..{ss[-1]} ({len(ss)})"
    return f"Seed{'s' if len(ss) != 1 else ''} {', '.join(map(str, ss))} ({len(ss)})"


def wall_words(rep: Any) -> str:
    """The wall time of this invocation, and what runs it reused (``--skip-existing``)."""
    text = (f"Wall time of this `dfrl paper` on this machine ({os.cpu_count()} cores): "
            f"**{rep.total_s:.0f} s**; federated runs {sum(rep.walls.values()):.0f} s of it "
            f"(standalone trainings and evaluations ran beside them).")
    reused = getattr(rep, "reused", {}) or {}
    if reused:
        known = [w for w in reused.values() if w == w]
        text += (f" {len(reused)} federated run(s) reused from an earlier invocation "
                 f"(--skip-existing), not in that time; their recorded wall time: "
                 f"{sum(known):.0f} s" + (f" ({len(reused) - len(known)} without a record)"
                                           if len(known) < len(reused) else "") + ".")
    return text


def controls_words(rep: Any, opts: Any) -> str:
    """What the controls and the reference were, or that there were none."""
    c = rep.controls
    if not (c.zero or c.shuffled_fed):
        return ("No negative control (`--no-control`): no test can be judged a test of "
                "learning.")
    return (f"Negative controls, runs that cannot have learned, with the same seeds, arenas and "
            f"evaluations: the **zero table** (never trained; greedy with random ties) and "
            f"federated Q-learning/average and standalone Q-learning in every arena trained on "
            f"**shuffled rewards** (the `reward_shuffle` trainer option: each update learns a "
            f"reward drawn from a seeded buffer of the last "
            f"{getattr(opts, 'shuffle_buffer', '?')} rewards observed, so the reward no longer "
            f"depends on state and action). The **off-policy reference** (federated "
            f"Q-learning/average and standalone Q-learning in R1 and R4 with random behaviour, "
            f"epsilon 1 throughout) is no control: Q-learning is off-policy, its greedy table "
            f"converges towards the same Q* as any other; test 1e compares with it.")


def _made_by(out: Path) -> str:
    p = read_provenance(out)
    return f"{describe(p)} (`provenance.json`)" if p else "an unrecorded version"


def _collisions(runs: list[SeedRun], role: str) -> list[float]:
    out = []
    for r in runs:
        last = max(int(e["iteration"]) for e in r.evals)
        sel = [float(e["collisions_per_1000"]) for e in r.evals
               if int(e["iteration"]) == last and e["role"] == role]
        out.append(float(np.mean(sel)) if sel else float("nan"))
    return out


def figures(out: Path, rep: Any, formats: Sequence[str] = ("png",),
            dpi: float | None = None) -> list[str]:
    """Draw the band figures in each of ``formats`` at ``dpi``; return the names of the first
    format's files (empty without matplotlib)."""
    names = []
    try:
        for algo in ("qlearning", "sarsa"):
            groups = {k: v for k, v in rep.fed.items() if k.startswith(algo)}
            groups[f"{algo} standalone"] = rep.standalone.get(algo, [])
            c = rep.controls
            if algo == "qlearning" and c.shuffled_fed:
                groups["control: shuffled rewards, federated"] = c.shuffled_fed
                groups["control: shuffled rewards, standalone"] = c.shuffled_sa
                groups["off-policy reference, federated"] = c.reference_fed
                groups["off-policy reference, standalone (R1, R4)"] = c.reference_sa
            paths = plot_groups(groups, out / "figures" / f"{algo}_bands.png",
                                f"{'Q-learning' if algo == 'qlearning' else 'SARSA'}",
                                formats, dpi)
            names.append(paths[0].name)
    except ImportError:
        return []
    return names


def write_report(out: Path, rep: Any, opts: Any, seeds: list[int]) -> Path:
    """Write ``OUT/report.md`` from a :class:`dfrl.experiments.science.reproduce.Reproduction`."""
    cfg_runs = next(iter(rep.fed.values()))
    iters = max(int(c["iteration"][-1]) for c in cfg_runs[0].curves.values() if len(c))
    L = ["# dFRL: the paper's experiment, several seeds, observations as tests", "",
         f"{seeds_words(seeds)}; five robots in R1..R5, {iters} "
         f"iterations each; standalone baselines with the same seeds and budget. "
         + controls_words(rep, opts) + " Greedy evaluations at "
         f"{opts.points} points of every run, {opts.eval_steps} steps per table and arena "
         f"({opts.eval_steps // opts.episode_steps} episodes of {opts.episode_steps} steps "
         f"from seeded random poses), in the robot's own arena and the held-out arenas h1 and "
         f"h2. Intervals: mean ± 95% Student-t half width over seeds.", "",
         wall_words(rep), "",
         f"Produced by {_made_by(out)}; every value of every run, one per row: `tidy.csv` "
         f"(run, seed, condition, robot, iteration, metric, value).", ""]
    names = figures(out, rep)
    L += ["## Figures", ""]
    L += [f"* figures/{n}" for n in names] or ["* (no figures: matplotlib is not installed)"]
    L += ["", "Per run and seed: `seed<S>/<run>/` (q_sum.png, cumulative_reward.png, "
          "metrics.csv, evaluations.csv).", "",
          "## Final numbers (mean ± 95% half width over seeds)", "",
          "| runs | final sum Q (robots' mean) | Q-sum growth in last quarter | greedy score own "
          "| greedy score held-out | collisions/1000 own | collisions/1000 held-out |",
          "|---|---|---|---|---|---|---|"]
    groups = dict(rep.fed)
    groups.update({f"{k} standalone": v for k, v in rep.standalone.items()})
    c = rep.controls
    if c.shuffled_fed:
        groups["control: shuffled rewards, federated"] = c.shuffled_fed
        groups["control: shuffled rewards, standalone"] = c.shuffled_sa
        groups["off-policy reference, federated"] = c.reference_fed
        groups["off-policy reference, standalone (R1, R4)"] = c.reference_sa
    for name, runs in groups.items():
        L.append(f"| {name} | {_iv([float(mean_q(r)[-1]) for r in runs])} | "
                 f"{_iv([late_growth(mean_q(r)) for r in runs])} | "
                 f"{_iv([final_score(r, 'own') for r in runs])} | "
                 f"{_iv([final_score(r, 'held_out') for r in runs])} | "
                 f"{_iv(_collisions(runs, 'own'))} | {_iv(_collisions(runs, 'held_out'))} |")
    if c.zero:
        L.append(f"| control: zero table (never trained) | 0 | - | "
                 f"{_iv([final_score(r, 'own') for r in c.zero])} | "
                 f"{_iv([final_score(r, 'held_out') for r in c.zero])} | "
                 f"{_iv(_collisions(c.zero, 'own'))} | {_iv(_collisions(c.zero, 'held_out'))} |")
    zero = next(iter(cfg_runs)).zero_score
    L += ["", "Zero table (greedy with random ties = a uniform random policy), score per arena: "
          + ", ".join(f"{a} {v:.2f}" for a, v in zero.items()) + ".", "",
          "## The paper's observations as tests", ""]
    tests = paper_tests(rep.fed, rep.standalone, c)
    L += tests_markdown(tests)
    L += ["## Summary", ""] + summary_markdown(tests)
    L += ["", "Caveats: our e-puck, reward and state discretisation are our own reconstruction "
          "(robots/README.md); absolute values are not comparable with the paper's. The "
          "saturation tests use the sum of Q-values, which with a constant learning rate keeps "
          "moving; robots/README.md gives the budgets at which it flattens."]
    path = Path(out) / "report.md"
    path.write_text("\n".join(L) + "\n", encoding="utf-8")
    return path
