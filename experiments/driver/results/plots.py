"""Figures of a federated experiment (matplotlib), in the paper's style: one line per robot
against iterations, for the sum of Q-values and for the cumulative reward. Each figure is
written in the formats asked for (PNG by default; PDF and SVG are vector formats for print) at
the resolution asked for (``dpi``: a figure's own screen default, 110, unless given; 300 for
print). The curves end with the last share: a row of ``metrics.csv`` holds the sum at the end of
its iteration, after that iteration's share (:mod:`dfrl.experiments.driver.results.metrics`),
so a robot's last row is the sum of the table it ended with; every row is drawn.

matplotlib is an optional extra (``pip install dfrl[plot]``); it is imported when a figure is
drawn, through its object-oriented API (no pyplot state, no backend switch).
"""
from __future__ import annotations

import csv
import json
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from dfrl.experiments.driver.results.metrics import read_metrics
# the file formats and resolution of every figure of dfrl (re-exported: callers import them here)
from dfrl.robots.figure_files import FORMATS, SCREEN_DPI, parse_formats, save_figure  # noqa: F401

COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown",
           "tab:pink", "tab:gray", "tab:olive", "tab:cyan")

LABELS = {"q_sum": "sum of Q-values", "cumulative_reward": "cumulative reward"}

def new_figure(**kwargs: Any) -> Any:
    """A matplotlib ``Figure`` with constrained layout (saved with ``savefig``).

    Raises
    ------
    ImportError
        matplotlib is not installed.
    """
    from matplotlib.figure import Figure

    return Figure(layout="constrained", **kwargs)


def robot_label(robot: str, arenas: Mapping[str, str]) -> str:
    """``R2 (R4)`` for robot r2 in arena r4; ``R1`` when robot and arena share a name."""
    arena = arenas.get(robot, "")
    name = robot.upper()
    return f"{name} ({arena.upper()})" if arena and arena.lower() != robot.lower() else name


def draw_lines(ax: Any, curves: Mapping[str, np.ndarray], field: str,
               arenas: Mapping[str, str] | None = None) -> list[Any]:
    """One line per robot of ``field`` against iterations on ``ax``, every row of the curve
    (so the last point is after the last share); return the lines."""
    lines = []
    for (robot, cur), colour in zip(curves.items(), COLOURS * 3):
        if len(cur):
            lines += ax.plot(cur["iteration"], cur[field], color=colour, lw=1.3,
                             label=robot_label(robot, arenas or {}))
    return lines


def plot_metric(curves: Mapping[str, np.ndarray], field: str, path: str | Path, title: str,
                arenas: Mapping[str, str] | None = None, shares: list[int] | None = None,
                formats: Sequence[str] = ("png",), dpi: float | None = None) -> list[Path]:
    """One figure: ``field`` against iterations, one line per robot.

    Parameters
    ----------
    curves : mapping robot -> structured array with ``iteration`` and ``field``
    field : str
        ``q_sum`` or ``cumulative_reward``.
    path : str or Path
    title : str
    arenas : mapping robot -> arena name, optional (legend)
    shares : list of int, optional
        Iterations at which tables were shared (drawn as faint vertical lines).
    formats, dpi
        See :func:`save_figure`; the files written are returned.
    """
    fig = new_figure(figsize=(6.4, 4.4))
    ax = fig.subplots()
    draw_lines(ax, curves, field, arenas)
    for x in shares or []:
        ax.axvline(x, color="0.85", lw=0.6, zorder=0)
    ax.set_xlabel("iterations")
    ax.set_ylabel(LABELS.get(field, field))
    ax.set_title(textwrap.fill(title, 70), fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return save_figure(fig, path, formats, dpi)


def plot_both(curves: Mapping[str, np.ndarray], path: str | Path, title: str,
              arenas: Mapping[str, str] | None = None, formats: Sequence[str] = ("png",),
              dpi: float | None = None) -> list[Path]:
    """Sum of Q-values and cumulative reward side by side (files as :func:`save_figure`)."""
    fig = new_figure(figsize=(11, 4.2))
    axes = fig.subplots(1, 2)
    for ax, field in zip(axes, ("q_sum", "cumulative_reward")):
        draw_lines(ax, curves, field, arenas)
        ax.set_xlabel("iterations")
        ax.set_ylabel(LABELS[field])
        ax.set_title(LABELS[field][0].upper() + LABELS[field][1:])
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, formats, dpi)


def share_iterations(out_dir: Path) -> list[int]:
    """Iterations of the shares of the first robot (the boundaries)."""
    files = sorted(out_dir.glob("shares_*.csv"))
    if not files:
        return []
    with open(files[0], newline="", encoding="utf-8") as fh:
        return [int(r["iteration"]) for r in csv.DictReader(fh)]


def plot_experiment(out_dir: str | Path, title: str = "", formats: Sequence[str] = ("png",),
                    dpi: float | None = None) -> list[Path]:
    """Draw ``q_sum``, ``cumulative_reward`` and ``curves`` from ``metrics.csv``, each in every
    format of ``formats`` (``.png``, ``.pdf``, ``.svg``) at ``dpi`` (see :func:`save_figure`);
    return the files written, figure by figure."""
    out = Path(out_dir)
    curves = read_metrics(out / "metrics.csv")
    if not curves:
        return []
    arenas: dict[str, str] = {}
    algos: set[str] = set()
    cfg_path = out / "config.json"
    if cfg_path.is_file():
        cfg = json.loads(cfg_path.read_text(encoding="utf-8"))
        for r in cfg.get("robots", []) + [j["robot"] for j in cfg.get("joins", [])]:
            arenas[r["id"]] = r["arena"]
            algos.add(r.get("algo", "qlearning"))
    shares = share_iterations(out)
    from dfrl.robots.learners import LEARNERS, is_tabular

    function = sorted(a for a in algos if a in LEARNERS and not is_tabular(a))
    note = f" ({', '.join(function)}: sum of parameters)" if function else ""
    return [
        *plot_metric(curves, "q_sum", out / "q_sum.png", f"Sum of Q-values{note}: {title}",
                     arenas, shares, formats, dpi),
        *plot_metric(curves, "cumulative_reward", out / "cumulative_reward.png",
                     f"Cumulative reward: {title}", arenas, shares, formats, dpi),
        *plot_both(curves, out / "curves.png", title, arenas, formats, dpi),
    ]
