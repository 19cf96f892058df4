"""The questions' part of ``report.md`` and the files that hold every number of it:
``questions.csv`` (one row per contrast: estimate, interval, p, Holm-adjusted p, verdict,
delta, the detectable effect and the seeds delta needs) and ``contrasts_by_seed.csv`` (the
per-seed values each contrast was computed from).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from dfrl.experiments.science.questions.answers import Answered, Answers
from dfrl.experiments.science.questions.catalogue import TITLES
from dfrl.experiments.science.questions.contrast import ALPHA, POWER, Contrast, MOST_SEEDS
from dfrl.experiments.science.questions.measures import arena_matrix, runs_of

QUESTIONS_FILE = "questions.csv"
BY_SEED_FILE = "contrasts_by_seed.csv"
COLUMNS = (
    "question",
    "contrast",
    "a",
    "b",
    "role",
    "measure",
    "side",
    "delta",
    "n",
    "seeds",
    "a_mean",
    "b_mean",
    "estimate",
    "low",
    "high",
    "sd",
    "p",
    "p_adjusted",
    "verdict",
    "detectable",
    "seeds_for_delta",
    "collisions_estimate",
    "collisions_low",
    "collisions_high",
)
PRIMARY = {
    "L": "greedy score in the robot's own arena (held-out episodes), end of the run",
    "F": "greedy score in the robot's own arena (held-out episodes), end of the run",
    "T": "greedy score in the arenas the robot never learnt in, end of the run",
    "M": "greedy score in the robot's own arena (held-out episodes), end of the run",
}


def _f(x: float, digits: int = 3) -> str:
    return "n/a" if not math.isfinite(x) else f"{x:+.{digits}f}"


def _ci(c: Contrast) -> str:
    low, high = c.interval()
    return f"{_f(c.estimate)} [{_f(low)}, {_f(high)}]"


def _p(p: float) -> str:
    return "n/a" if not math.isfinite(p) else (f"{p:.2g}" if p >= 1e-4 else "<1e-4")


def _seeds_for(c: Contrast) -> str:
    n = c.seeds_needed()
    return (
        f"> {MOST_SEEDS}"
        if n is None and math.isfinite(c.sd) and c.sd > 0
        else ("n/a" if n is None else str(n))
    )


def _mean(xs: tuple[float, ...]) -> float:
    return float(np.mean(xs)) if xs else float("nan")


def markdown(ans: Answers) -> list[str]:
    """The report's lines: the checks, then each question with its rows and its answer."""
    L = [
        "## The questions",
        "",
        f"Each row is one contrast A - B, paired by seed (the same seeds, arenas and evaluation "
        f"episodes), with its 95% t interval and one-sided p (two-sided for M and the checks); "
        f"Holm's correction within each question's family (adjusted p); verdicts: holds "
        f"(adjusted p < {ALPHA:g}), refuted (the interval excludes an effect of delta), not "
        f"significant at n = K with D, the smallest effect the row detects with "
        f"{POWER:.0%} power at level {ALPHA:g} / m (m rows in the family), and the seeds "
        f"delta needs at the spread measured. Every number: `questions.csv`, "
        f"`contrasts_by_seed.csv`.",
        "",
    ]
    L += [
        f"### {TITLES['C']}",
        "",
        "| control - untrained | n | difference [95%] | D | check |",
        "|---|---|---|---|---|",
    ]
    for check in ans.checks:
        L.append(
            f"| {check.row.a} | {check.contrast.n} | {_ci(check.contrast)} | "
            f"{check.contrast.detectable():.3g} | {check.words()} |"
        )
    if not ans.checks:
        L.append("| (no learning control in the study) | | | | no L row can be judged |")
    L.append("")
    for q in ("L", "F", "T", "M"):
        rows = ans.questions.get(q, [])
        L += [
            f"### {q}. {TITLES[q]}",
            "",
            f"Primary measure: {PRIMARY[q]}; delta = {ans.deltas[q]:g}.",
            "",
        ]
        if not rows:
            L += ["No condition of this study answers it.", ""]
            continue
        L += [
            "| A - B | n | A | B | A - B [95%] | p | Holm p | verdict | D | seeds for delta "
            "| collisions/1000 A - B [95%] |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for a in rows:
            c, j = a.judged.contrast, a.judged
            L.append(
                f"| {a.row.label} | {c.n} | {_mean(c.a):.3f} | {_mean(c.b):.3f} | {_ci(c)} "
                f"| {_p(c.p)} | {_p(j.p_adjusted)} | {j.words()} | {c.detectable():.3g} | "
                f"{_seeds_for(c)} | {_ci(a.collisions)} |"
            )
        L.append("")
        L += _answer_lines(q, ans, rows) + [""]
    return L


def _answer_lines(q: str, ans: Answers, rows: list[Answered]) -> list[str]:
    if q == "L":
        return [
            "**Answer**: "
            + "; ".join(f"{run}: {v}" for run, v in ans.learns().items())
            + " (a condition learns when both its rows hold)."
        ]
    held = [a.row.label for a in rows if a.judged.outcome.value == "holds"]
    refuted = [a.row.label for a in rows if a.judged.outcome.value == "refuted"]
    worst_d = max((a.judged.contrast.detectable() for a in rows), default=float("nan"))
    text = (
        f"**Answer**: holds for {', '.join(held) or 'no row'}; refuted for "
        f"{', '.join(refuted) or 'no row'}; the largest smallest-detectable effect "
        f"D = {worst_d:.3g} against delta = {ans.deltas[q]:g}"
    )
    return [
        text
        + (
            " (the study had the power for delta)."
            if worst_d <= ans.deltas[q]
            else " (more seeds needed: see the rows' seeds for delta)."
        )
    ]


def aggregates_markdown(ans: Answers, resamples: int = 2000, seed: int = 0) -> list[str]:
    """The interquartile mean of each condition's own-arena score over seeds x arenas, with a
    95% stratified bootstrap interval (rliable: arenas as tasks, seeds as runs)."""
    try:
        from rliable import library, metrics
    except ImportError as exc:
        return ["## Aggregates", "", f"(rliable is not installed: {exc})", ""]
    L = [
        "## Aggregates (rliable)",
        "",
        "Interquartile mean of the final own-arena greedy score over seeds x arenas (each "
        "arena a task, each seed a run), 95% stratified bootstrap interval "
        f"({resamples} resamples, seeded): the RL field's robust summary of a condition, "
        "beside the paired contrasts above.",
        "",
        "| condition | seeds | IQM [95%] |",
        "|---|---|---|",
    ]
    for run in runs_of(ans.values):
        m = arena_matrix(ans.values, run)
        m = m[~np.isnan(m).any(axis=1)] if m.size else m
        if m.shape[0] < 2 or m.shape[1] == 0:
            continue
        np.random.seed(seed)  # rliable draws from numpy's global generator
        est, ci = library.get_interval_estimates(
            {run: m}, lambda s: np.array([metrics.aggregate_iqm(s)]), reps=resamples
        )
        L.append(
            f"| {run} | {m.shape[0]} | {est[run][0]:.3f} [{ci[run][0][0]:.3f}, "
            f"{ci[run][1][0]:.3f}] |"
        )
    return L + [""]


def rows_of(ans: Answers) -> Iterator[tuple]:
    """``questions.csv`` rows."""
    for check in ans.checks:
        yield _row(
            check.row,
            check.contrast,
            check.contrast.p,
            float("nan"),
            "passes" if check.passes else check.words(),
            None,
        )
    for q in ("L", "F", "T", "M"):
        for a in ans.questions.get(q, []):
            yield _row(
                a.row,
                a.judged.contrast,
                a.judged.contrast.p,
                a.judged.p_adjusted,
                a.judged.words(),
                a.collisions,
            )


def _row(row, c: Contrast, p: float, padj: float, verdict: str, coll: Contrast | None) -> tuple:
    low, high = c.interval()
    clow, chigh = coll.interval() if coll is not None else (float("nan"), float("nan"))
    return (
        row.question,
        row.label,
        row.a,
        row.b,
        row.role,
        row.measure,
        row.side,
        c.delta,
        c.n,
        " ".join(map(str, c.seeds)),
        _mean(c.a),
        _mean(c.b),
        c.estimate,
        low,
        high,
        c.sd,
        p,
        padj,
        verdict,
        c.detectable(),
        c.seeds_needed() or "",
        coll.estimate if coll is not None else float("nan"),
        clow,
        chigh,
    )


def by_seed_rows(ans: Answers) -> Iterator[tuple]:
    """``contrasts_by_seed.csv`` rows: question, contrast, measure, seed, a, b, a - b."""
    items: list[tuple[str, str, Contrast]] = [
        (c.row.question, c.row.label, c.contrast) for c in ans.checks
    ]
    for q in ("L", "F", "T", "M"):
        for a in ans.questions.get(q, []):
            items.append((q, a.row.label, a.judged.contrast))
            items.append((q, a.row.label + " [collisions]", a.collisions))
    for q, label, c in items:
        for s, x, y in zip(c.seeds, c.a, c.b):
            yield (q, label, s, x, y, x - y)


def write_files(out: Path, ans: Answers) -> tuple[Path, Path]:
    """Write ``questions.csv`` and ``contrasts_by_seed.csv`` into ``out``."""
    q_path, s_path = Path(out) / QUESTIONS_FILE, Path(out) / BY_SEED_FILE
    with open(q_path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        w.writerows(rows_of(ans))
    with open(s_path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(("question", "contrast", "seed", "a", "b", "difference"))
        w.writerows(by_seed_rows(ans))
    return q_path, s_path
