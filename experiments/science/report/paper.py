"""``report.md`` of ``dfrl paper``: the questions with their contrasts, checks and verdicts
(:mod:`dfrl.experiments.science.questions`), robust aggregates, figures with bands, and the
diagnostics (the sum of Q-values and its late growth, the off-policy reference), which are
printed as numbers, never as tests. ``questions.md`` (:func:`write_questions_report`) is the
questions' part alone, written by ``dfrl paper --from``."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.provenance import describe, read_provenance
from dfrl.experiments.science.curves import late_growth
from dfrl.experiments.science.questions.answers import Answers
from dfrl.experiments.science.questions.catalogue import UNTRAINED
from dfrl.experiments.science.questions.report import aggregates_markdown, markdown
from dfrl.experiments.science.report.bands import plot_groups
from dfrl.experiments.science.report.measures import SeedRun, final_score, mean_q
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
    text = (
        f"Wall time of this `dfrl paper` on this machine ({os.cpu_count()} cores): "
        f"**{rep.total_s:.0f} s**; federated runs {sum(rep.walls.values()):.0f} s of it "
        f"(standalone trainings and evaluations ran beside them)."
    )
    reused = getattr(rep, "reused", {}) or {}
    if reused:
        known = [w for w in reused.values() if w == w]
        text += (
            f" {len(reused)} federated run(s) reused from an earlier invocation "
            f"(--skip-existing), not in that time; their recorded wall time: "
            f"{sum(known):.0f} s"
            + (
                f" ({len(reused) - len(known)} without a record)"
                if len(known) < len(reused)
                else ""
            )
            + "."
        )
    return text


def controls_words(rep: Any, opts: Any) -> str:
    """What the controls were, or that there were none."""
    if UNTRAINED not in rep.runs:
        return "No control (`--no-control`): question L cannot be judged."
    return (
        f"Controls, through the same pipeline (seeds, arenas, evaluation episodes): the "
        f"**untrained tables** (seeded random values, never trained: a fixed arbitrary "
        f"greedy policy, like every trained table's) and, per algorithm, standalone and "
        f"federated, a **learning control** trained on centred shuffled rewards with no "
        f"bootstrapping (`reward_shuffle`, buffer {getattr(opts, 'shuffle_buffer', '?')}: "
        f'robots/README.md, "Controls", says what it is and measures it). The all-zero '
        f"table (random ties at every step: a random walk) is a diagnostic."
    )


def _made_by(out: Path) -> str:
    p = read_provenance(out)
    return f"{describe(p)} (`provenance.json`)" if p else "an unrecorded version"


def _collisions(runs: list[SeedRun], role: str) -> list[float]:
    out = []
    for r in runs:
        if not r.evals:
            continue
        last = max(int(e["iteration"]) for e in r.evals)
        sel = [
            float(e["collisions_per_1000"])
            for e in r.evals
            if int(e["iteration"]) == last and e["role"] == role
        ]
        out.append(float(np.mean(sel)) if sel else float("nan"))
    return out


def figures(
    out: Path, rep: Any, formats: Sequence[str] = ("png",), dpi: float | None = None
) -> list[str]:
    """Draw the band figures (one per algorithm: its conditions and its controls) in each of
    ``formats`` at ``dpi``; return the names of the first format's files (empty without
    matplotlib)."""
    names = []
    try:
        for algo in ("qlearning", "sarsa"):
            groups = {
                k: v
                for k, v in rep.runs.items()
                if algo in k.split("/") and any(len(r.curves) for r in v)
            }
            if not groups:
                continue
            paths = plot_groups(
                groups,
                out / "figures" / f"{algo}_bands.png",
                f"{'Q-learning' if algo == 'qlearning' else 'SARSA'}",
                formats,
                dpi,
            )
            names.append(paths[0].name)
    except ImportError:
        return []
    return names


def _numbers(rep: Any) -> list[str]:
    L = [
        "## Final numbers and diagnostics (mean ± 95% half width over seeds)",
        "",
        "Diagnostics, not tests: the sum of Q-values rises whatever a robot learns (positive "
        "rewards, zero start) and its growth in the last quarter says how far from flat it "
        "is; the off-policy reference (`--diagnostics`: Q-learning from random behaviour) "
        "learns like any other Q-learner.",
        "",
        "| condition | final sum Q (robots' mean) | Q-sum growth in last quarter | greedy "
        "score own | greedy score held-out | collisions/1000 own | collisions/1000 held-out |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, runs in rep.runs.items():
        curved = [r for r in runs if r.curves]
        q = (
            (
                f"{_iv([float(mean_q(r)[-1]) for r in curved])} | "
                f"{_iv([late_growth(mean_q(r)) for r in curved])}"
            )
            if curved
            else "0 | -"
        )
        L.append(
            f"| {name} | {q} | {_iv([final_score(r, 'own') for r in runs])} | "
            f"{_iv([final_score(r, 'held_out') for r in runs])} | "
            f"{_iv(_collisions(runs, 'own'))} | {_iv(_collisions(runs, 'held_out'))} |"
        )
    return L + [""]


def _summary(ans: Answers) -> list[str]:
    L = ["## Summary", ""]
    for run, verdict in ans.learns().items():
        L.append(f"- L, {run}: {verdict}")
    for c in ans.checks:
        L.append(f"- check, {c.row.a}: {c.words()}")
    for q in ("F", "T", "M"):
        for a in ans.questions.get(q, []):
            L.append(f"- {q}, {a.row.label}: {a.judged.words()}")
    return L + [""]


def write_report(out: Path, rep: Any, opts: Any, seeds: list[int]) -> Path:
    """Write ``OUT/report.md`` from a :class:`dfrl.experiments.science.reproduce.Reproduction`."""
    curved = [c for runs in rep.runs.values() for r in runs for c in r.curves.values() if len(c)]
    iters = max((int(c["iteration"][-1]) for c in curved), default=0)
    L = [
        "# dFRL: the paper's experiment, several seeds, questions answered by contrasts",
        "",
        f"{seeds_words(seeds)}; five robots in R1..R5, {iters} iterations each; standalone "
        f"robots with the same seeds and budget. " + controls_words(rep, opts) + " Greedy "
        f"evaluations at {opts.points} points of every run, {opts.eval_steps} steps per table "
        f"and arena ({opts.eval_steps // opts.episode_steps} episodes of {opts.episode_steps} "
        f"steps from seeded random poses, the same for every condition of a seed), in the "
        f"robot's own arena and the held-out arenas h1 and h2.",
        "",
        wall_words(rep),
        "",
        f"Produced by {_made_by(out)}. The data: `evaluations.csv` (every greedy evaluation, "
        f"one row each; `dfrl paper --from {out}` judges it again), `tidy.csv` (every curve "
        f"and evaluation, one value per row).",
        "",
    ]
    L += _summary(rep.answers)
    L += markdown(rep.answers)
    L += aggregates_markdown(rep.answers, resamples=opts.resamples)
    names = figures(out, rep)
    L += ["## Figures", ""]
    L += [f"* figures/{n}" for n in names] or ["* (no figures: matplotlib is not installed)"]
    L += [
        "",
        "Per run and seed: `seed<S>/<run>/` (q_sum.png, cumulative_reward.png, "
        "metrics.csv, evaluations.csv).",
        "",
    ]
    L += _numbers(rep)
    L += [
        "Caveats: our e-puck, reward and state discretisation are our own reconstruction "
        "(robots/README.md); absolute values are not comparable with the paper's."
    ]
    path = Path(out) / "report.md"
    path.write_text("\n".join(L) + "\n", encoding="utf-8")
    return path


def write_questions_report(
    out: Path,
    ans: Answers,
    source: Path,
    intro: Sequence[str] | None = None,
    name: str = "questions.md",
    resamples: int = 2000,
) -> Path:
    """``OUT/questions.md``: the questions judged from ``source/evaluations.csv`` alone (or,
    with ``intro``, those lines first: a study that ran and judged in one go)."""
    deltas = (
        "Smallest effects of interest: "
        + ", ".join(f"{q} {d:g}" for q, d in ans.deltas.items())
        + "."
    )
    if intro is None:
        L = [
            "# dFRL: the questions, judged again from the evaluations",
            "",
            f"From `{Path(source) / 'evaluations.csv'}`; nothing was run. " + deltas,
            "",
        ]
    else:
        L = list(intro) + ["", deltas, ""]
    L += _summary(ans) + markdown(ans) + aggregates_markdown(ans, resamples=resamples)
    path = Path(out) / name
    path.write_text("\n".join(L) + "\n", encoding="utf-8")
    return path
