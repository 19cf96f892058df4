"""``live_evaluations.csv``: the greedy evaluations the robots ran while they learned (one row per
robot and evaluation), joined from their ``eval_<robot>.csv`` files
(:mod:`dfrl.experiments.robot_host.evaluate`, option ``eval_every``).

The columns are :data:`~dfrl.experiments.robot_host.evaluate.EVAL_FIELDS`. (The paper study's
offline evaluations of a run's table history, :mod:`dfrl.experiments.science.studies.history`, write a
file of the same name with columns of their own, for runs without ``eval_every``.)
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from dfrl.experiments.robot_host.evaluate import EVAL_FIELDS

__all__ = ["EVALUATIONS_FILE", "last_evaluations", "merge_evaluations", "read_evaluations"]

#: Name of the file in a results folder.
EVALUATIONS_FILE = "live_evaluations.csv"


def merge_evaluations(out_dir: str | Path, robots: list[str]) -> Path | None:
    """Concatenate the ``eval_<robot>.csv`` files into ``live_evaluations.csv`` (robot order
    kept, a torn last line skipped); None, and no file, when no robot evaluated."""
    out = Path(out_dir)
    rows: list[str] = []
    for robot in robots:
        src = out / f"eval_{robot}.csv"
        if not src.is_file():
            continue
        with open(src, encoding="utf-8") as fh:
            next(fh, None)
            rows += [line for line in fh
                     if line.count(",") == len(EVAL_FIELDS) - 1 and line.endswith("\n")]
    if not rows:
        return None
    target = out / EVALUATIONS_FILE
    with open(target, "w", newline="", encoding="utf-8") as dst:
        dst.write(",".join(EVAL_FIELDS) + "\n")
        dst.writelines(rows)
    return target


def read_evaluations(path: str | Path) -> list[dict[str, Any]]:
    """``live_evaluations.csv`` (or one ``eval_<robot>.csv``) back, numbers as numbers."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows: list[dict[str, Any]] = list(csv.DictReader(fh))
    for r in rows:
        r["iteration"], r["steps"] = int(r["iteration"]), int(r["steps"])
        for key in EVAL_FIELDS[4:]:
            r[key] = float(r[key])
    return rows


def last_evaluations(out_dir: str | Path) -> dict[str, dict[str, Any]]:
    """Robot -> its last evaluation (the row with the highest iteration) in the folder's
    ``live_evaluations.csv``; empty when there is none, or it is not this module's file."""
    path = Path(out_dir) / EVALUATIONS_FILE
    if not path.is_file():
        return {}
    with open(path, encoding="utf-8") as fh:
        if fh.readline().strip() != ",".join(EVAL_FIELDS):
            return {}
    last: dict[str, dict[str, Any]] = {}
    for r in read_evaluations(path):
        if r["robot"] not in last or r["iteration"] >= last[r["robot"]]["iteration"]:
            last[r["robot"]] = r
    return last
