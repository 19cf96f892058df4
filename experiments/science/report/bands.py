"""Figures over seeds: the mean of each curve with its 95% t band (matplotlib, PNG)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from dfrl.experiments.science.report.measures import SeedRun, mean_q, scores
from dfrl.experiments.driver.results.plots import COLOURS, new_figure, save_figure
from dfrl.experiments.science.statistics import t975


def band(curves: Sequence[np.ndarray] | Sequence[Sequence[float]]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and 95% t half width over curves (rows) of equal length, shape (n,) each."""
    a = np.asarray(curves, dtype=np.float64)
    mean = a.mean(axis=0)
    if len(a) < 2:
        return mean, np.zeros_like(mean)
    return mean, t975(len(a) - 1) * a.std(axis=0, ddof=1) / np.sqrt(len(a))


def _mean_reward(run: SeedRun) -> np.ndarray:
    n = min(len(c) for c in run.curves.values())
    return np.mean([c["cumulative_reward"][:n] for c in run.curves.values()], axis=0)


def _score_curve(runs: Sequence[SeedRun], role: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    per = [scores(r, role) for r in runs]
    its = sorted(set.intersection(*(set(p) for p in per))) if per else []
    m, h = band([[p[i] for i in its] for p in per]) if its else (np.array([]), np.array([]))
    return np.array(its), m, h


def plot_groups(
    groups: Mapping[str, Sequence[SeedRun]],
    path: Path,
    title: str,
    formats: Sequence[str] = ("png",),
    dpi: float | None = None,
) -> list[Path]:
    """Three panels: robots' mean sum of Q-values, mean cumulative reward, and the greedy
    score (own arena solid, held-out dashed), one colour per group, mean over seeds with a
    95% band; written in each of ``formats`` (see
    :func:`dfrl.experiments.driver.results.plots.save_figure`, screen default 100 dpi)."""
    fig = new_figure(figsize=(15, 4.4))
    axes = fig.subplots(1, 3)
    for (name, runs), colour in zip(groups.items(), COLOURS * 2):
        if not runs:
            continue
        for ax, fn in zip(axes[:2], (mean_q, _mean_reward)):
            ys = [fn(r) for r in runs]
            n = min(len(y) for y in ys)
            it = np.arange(1, n + 1)
            m, h = band([y[:n] for y in ys])
            ax.plot(it, m, color=colour, lw=1.3, label=f"{name} (n={len(runs)})")
            ax.fill_between(it, m - h, m + h, color=colour, alpha=0.2, lw=0)
        for role, style in (("own", "-"), ("held_out", "--")):
            its, m, h = _score_curve(runs, role)
            if len(its):
                axes[2].plot(
                    its,
                    m,
                    style,
                    color=colour,
                    marker="o",
                    ms=3,
                    lw=1.3,
                    label=f"{name}, {role.replace('_', '-')}",
                )
                axes[2].fill_between(its, m - h, m + h, color=colour, alpha=0.15, lw=0)
    for ax, label in zip(
        axes,
        (
            "mean sum of Q-values",
            "mean cumulative reward",
            "greedy score (progress - 0.05 x collisions/1000)",
        ),
    ):
        ax.set_xlabel("iterations")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=7)
    fig.suptitle(title + " (mean over seeds, 95% band)", fontsize=10)
    return save_figure(fig, path, formats, dpi, default_dpi=100)
