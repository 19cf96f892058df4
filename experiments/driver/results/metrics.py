"""``metrics.csv``: the robots' learning curves (one row per robot and iteration)."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from dfrl.experiments.driver.results.tables import table_sum

METRICS_FIELDS = ("robot", "iteration", "q_sum", "cumulative_reward", "collisions")

_CURVE_DTYPE = np.dtype([("iteration", np.int64), ("q_sum", np.float64),
                         ("cumulative_reward", np.float64), ("collisions", np.int64)])


def merge_metrics(out_dir: str | Path, robots: list[str]) -> Path:
    """Concatenate the ``metrics_<robot>.csv`` files into ``metrics.csv`` (robot order kept).

    A robot's last metrics row is taken before the last share; when its saved table
    (``tables/<robot>.npy``, written after it) sums to something else, one more row at the
    same iteration carries that sum, so that curves and summary end with the last share.
    """

    out = Path(out_dir)
    target = out / "metrics.csv"
    with open(target, "w", newline="", encoding="utf-8") as dst:
        dst.write(",".join(METRICS_FIELDS) + "\n")
        for robot in robots:
            src = out / f"metrics_{robot}.csv"
            if not src.is_file():
                continue
            last = None
            with open(src, encoding="utf-8") as fh:
                next(fh, None)
                for line in fh:
                    if line.count(",") == 4 and line.endswith("\n"):   # skip a torn last line
                        dst.write(line)
                        last = line.rstrip("\n").split(",")
            final = table_sum(out, robot)
            if last is not None and final is not None and float(last[2]) != final:
                dst.write(",".join([robot, last[1], repr(final), last[3], last[4]]) + "\n")
    return target


def read_metrics(path: str | Path) -> dict[str, np.ndarray]:
    """``metrics.csv`` (or a per-robot file) -> robot -> structured array (iteration, q_sum,
    cumulative_reward, collisions), in file order."""
    rows: dict[str, list[tuple[int, float, float, int]]] = {}
    with open(path, newline="", encoding="utf-8") as fh:
        for r in csv.DictReader(fh):
            rows.setdefault(r["robot"], []).append(
                (int(r["iteration"]), float(r["q_sum"]), float(r["cumulative_reward"]),
                 int(r["collisions"])))
    return {robot: np.array(v, dtype=_CURVE_DTYPE) for robot, v in rows.items()}
