"""Files and figure of a transfer experiment."""

from __future__ import annotations

import csv
import json
from dataclasses import asdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dfrl.experiments.science.transfer.model import RunResult, TransferResult


def write_outputs(result: TransferResult, out: Path) -> None:
    """Write ``config.json``, ``runs.csv``, ``curves.csv``, ``summary.json``, ``transfer.png``."""
    out.mkdir(parents=True, exist_ok=True)
    doc = {
        "transfer": result.config.to_dict(),
        "trainer": result.trainer_config.to_dict(),
        "table": asdict(result.table),
        "arena": result.arena_name,
    }
    (out / "config.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    with open(out / "runs.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(RunResult.CSV_FIELDS)
        for r in result.runs:
            writer.writerow([repr(v) if isinstance(v, float) else v for v in r.scalars().values()])
    with open(out / "curves.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(("seed", "condition", "iteration", "collisions", "cumulative_reward"))
        for r in result.runs:
            for it, c, rew in zip(
                r.curve_iteration.tolist(), r.curve_collisions.tolist(), r.curve_reward.tolist()
            ):
                writer.writerow((r.seed, r.condition, it, c, repr(rew)))
    (out / "summary.json").write_text(
        json.dumps(result.to_dict(), indent=2) + "\n", encoding="utf-8"
    )
    try:
        plot_transfer(result, out / "transfer.png")
    except ImportError:  # matplotlib is an optional extra
        pass


def plot_transfer(
    result: TransferResult, path: Path, formats: Sequence[str] = ("png",), dpi: float | None = None
) -> list[Path]:
    """Cumulative collisions and reward against iterations, mean over seeds, min-max band,
    in each of ``formats`` at ``dpi`` (:func:`dfrl.experiments.driver.results.plots.save_figure`,
    screen default 100 dpi); return the files written.

    Raises
    ------
    ImportError
        matplotlib is not installed (``pip install dfrl[plot]``).
    """
    from dfrl.experiments.driver.results.plots import new_figure, save_figure

    fig = new_figure(figsize=(10, 3.8))
    ax_c, ax_r = fig.subplots(1, 2)
    src = Path(result.table.path).parent.name + "/" + Path(result.table.path).name
    labels = {"init": f"from table ({src})", "zero": "from zeros"}
    for cond, colour in (("init", "tab:blue"), ("zero", "tab:red")):
        runs = [r for r in result.runs if r.condition == cond]
        it = runs[0].curve_iteration
        for ax, name in ((ax_c, "curve_collisions"), (ax_r, "curve_reward")):
            ys = np.stack([getattr(r, name) for r in runs]).astype(np.float64)
            ax.plot(
                it,
                ys.mean(axis=0),
                color=colour,
                lw=1.4,
                label=f"{labels[cond]}, mean of {len(runs)}",
            )
            if len(runs) > 1:
                ax.fill_between(it, ys.min(axis=0), ys.max(axis=0), color=colour, alpha=0.18, lw=0)
    ax_c.set_ylabel("cumulative collisions")
    ax_r.set_ylabel("cumulative reward")
    for ax in (ax_c, ax_r):
        ax.set_xlabel("iterations")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"Transfer into {result.arena_name} ({result.trainer_config.algo})")
    return save_figure(fig, path, formats, dpi, default_dpi=100)
