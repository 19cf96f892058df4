"""Figures (matplotlib, Agg backend): learning curves and arena top views, written as PNG
(default) or PDF/SVG at the resolution asked for (:func:`dfrl.robots.figure_files.save_figure`).

matplotlib is an optional dependency (``pip install dfrl[plot]``); it is imported here only.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from dfrl.robots.figure_files import save_figure

_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown")


def _pyplot():  # noqa: ANN202 - matplotlib module
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_learning_curves(
    curves: Mapping[str, np.ndarray | Sequence[np.ndarray]],
    path: str | Path,
    title: str,
    formats: Sequence[str] = ("png",),
    dpi: float | None = None,
    summed: str = "Q-values",
) -> Path:
    """Sum of Q-values (or of what ``summed`` names) and cumulative reward against
    iterations, one line per label.

    Parameters
    ----------
    curves : mapping of str to np.ndarray or a sequence of them
        Label -> structured metrics array with fields ``iteration``, ``q_sum`` and
        ``cumulative_reward`` (as returned by :func:`dfrl.robots.training.train`), or several
        such arrays of equal length (runs with different seeds): then the line is their mean
        and a band shows their minimum and maximum.
    path : str or Path
        File to write; its suffix is replaced by each of ``formats``.
    title : str
        Figure title.
    formats, dpi
        File formats (``png``, ``pdf``, ``svg``) and resolution (default 110 dpi).
    summed : str
        What the ``q_sum`` column sums, for the left panel's title and axis: ``Q-values``
        (a tabular learner's table) or ``parameters`` (a function learner's).

    Returns
    -------
    Path
        The first file written (the others beside it).
    """
    plt = _pyplot()
    fig, (ax_q, ax_r) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for (label, runs), colour in zip(curves.items(), _COLOURS):
        runs = [runs] if isinstance(runs, np.ndarray) else list(runs)
        it = runs[0]["iteration"]
        for ax, field in ((ax_q, "q_sum"), (ax_r, "cumulative_reward")):
            ys = np.stack([r[field] for r in runs])
            name = label if len(runs) == 1 else f"{label} (mean of {len(runs)} seeds)"
            ax.plot(it, ys.mean(axis=0), color=colour, lw=1.4, label=name)
            if len(runs) > 1:
                ax.fill_between(it, ys.min(axis=0), ys.max(axis=0), color=colour, alpha=0.18, lw=0)
    ax_q.set_xlabel("iterations")
    ax_q.set_ylabel(f"sum of {summed}")
    ax_q.set_title(f"Sum of {summed}")
    ax_r.set_xlabel("iterations")
    ax_r.set_ylabel("cumulative reward")
    ax_r.set_title("Cumulative reward")
    for ax in (ax_q, ax_r):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best")
    fig.suptitle(title)
    return _save(plt, fig, path, formats, dpi, 110)


def _save(
    plt,
    fig,
    path: str | Path,
    formats: Sequence[str],
    dpi: float | None,  # noqa: ANN001
    default_dpi: float,
) -> Path:
    """Write ``fig`` in each of ``formats`` and close it; the first file written."""
    try:
        return save_figure(fig, path, formats, dpi, default_dpi)[0]
    finally:
        plt.close(fig)


def plot_arena(
    image: np.ndarray,
    spec,
    path: str | Path,  # noqa: ANN001 - ArenaSpec
    rays: np.ndarray | None = None,
    formats: Sequence[str] = ("png",),
    dpi: float | None = None,
) -> Path:
    """Save a rendered top view with metric axes, the start pose and its heading.

    Parameters
    ----------
    image : np.ndarray, shape (h, w, 3), uint8
        Top view from :meth:`dfrl.robots.world.World.render_top` (covers the floor plus 5 cm).
    spec : ArenaSpec
    path : str or Path
        File to write; its suffix is replaced by each of ``formats``.
    rays : np.ndarray, shape (n_sensors, 2, 2), optional
        Sensor rays to draw (:meth:`dfrl.robots.epuck.EPuck.sensor_rays`).
    formats, dpi
        File formats (``png``, ``pdf``, ``svg``) and resolution (default 100 dpi).

    Returns
    -------
    Path
        The first file written.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.2, 5.2), constrained_layout=True)
    draw_arena(ax, image, spec, rays)
    return _save(plt, fig, path, formats, dpi, 100)


def draw_arena(ax, image: np.ndarray, spec, rays: np.ndarray | None = None) -> dict:  # noqa: ANN001
    """Draw a top view on matplotlib axes ``ax`` (see :func:`plot_arena`); return the artists:
    ``heading`` (the start pose's arrow, None for a random start) and ``rays`` (lines)."""
    w, d = spec.size
    half = (max(w, d) + 0.1) / 2
    ax.imshow(image, extent=(-half, half, -half, half), origin="upper")
    heading = None
    if spec.start.pose is not None:
        x, y, yaw = spec.start.pose
        heading = ax.annotate(
            "",
            xy=(x + 0.09 * math.cos(yaw), y + 0.09 * math.sin(yaw)),
            xytext=(x, y),
            arrowprops={"arrowstyle": "->", "color": "black", "lw": 1.5},
        )
        ax.text(x, y - 0.07, "start", ha="center", va="top", fontsize=8)
    else:
        ax.text(0, -half + 0.01, "start: random free pose", ha="center", va="bottom", fontsize=8)
    lines = []
    if rays is not None:
        for (x0, y0), (x1, y1) in np.asarray(rays):
            lines += ax.plot([x0, x1], [y0, y1], color="tab:red", lw=0.8, alpha=0.8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    n = len(spec.blocks)
    ax.set_title(f"{spec.name.upper()}: {w:g} m x {d:g} m, {n} block{'s' if n != 1 else ''}")
    return {"heading": heading, "rays": lines}


def plot_arena_overview(
    images: Mapping[str, np.ndarray],
    path: str | Path,
    formats: Sequence[str] = ("png",),
    dpi: float | None = None,
) -> Path:
    """All arenas side by side (one row), in ``formats`` at ``dpi`` (default 100); the first
    file written."""
    plt = _pyplot()
    n = len(images)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n, 2.9), constrained_layout=True)
    for ax, (name, img) in zip(np.atleast_1d(axes), images.items()):
        ax.imshow(img)
        ax.set_title(name.upper())
        ax.axis("off")
    return _save(plt, fig, path, formats, dpi, 100)
