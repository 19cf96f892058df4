"""One tidy long table per study: ``tidy.csv``, one measured value per row.

Columns: ``run, seed, condition, robot, iteration, metric, value``. ``run`` names the run
within the study (``qlearning/average``, ``standalone/sarsa``, ``N=5``), ``condition`` its
kind (``federated``, ``standalone``, ``control federated``, ...). Metrics of a curve are
``q_sum``, ``cumulative_reward`` and ``collisions``, sampled every ``step`` iterations and at
the last one; a greedy evaluation gives ``<measure>@<arena>`` (``score@h1``,
``collisions_per_1000@r1``). Read it with ``pandas.read_csv`` or any spreadsheet.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

#: The file name in a study's folder.
TIDY_FILE = "tidy.csv"
COLUMNS = ("run", "seed", "condition", "robot", "iteration", "metric", "value")
#: Curve columns written to the tidy table.
CURVE_METRICS = ("q_sum", "cumulative_reward", "collisions")
#: Evaluation measures written to the tidy table.
EVAL_METRICS = ("score", "collisions_per_1000", "progress")
#: Default spacing (iterations) of curve samples.
CURVE_STEP = 100

Row = tuple[str, int, str, str, int, str, float]


def curve_rows(
    run: str, seed: int, condition: str, curves: dict[str, np.ndarray], step: int = CURVE_STEP
) -> Iterator[Row]:
    """Rows of per-robot curves (structured arrays with an ``iteration`` column), every
    ``step`` iterations and the last row."""
    for robot, c in curves.items():
        if len(c) == 0:
            continue
        its = c["iteration"]
        fields = c.dtype.names or ()
        keep = np.nonzero(its % step == 0)[0].tolist()
        if not keep or keep[-1] != len(c) - 1:
            keep.append(len(c) - 1)
        for i in keep:
            for m in CURVE_METRICS:
                if m in fields:
                    yield (run, seed, condition, robot, int(its[i]), m, float(c[m][i]))


def evaluation_rows(
    run: str, seed: int, condition: str, evals: Iterable[dict[str, Any]]
) -> Iterator[Row]:
    """Rows of greedy evaluations (``robot, iteration, arena`` and the measures)."""
    for e in evals:
        for m in EVAL_METRICS:
            if m in e:
                yield (
                    run,
                    seed,
                    condition,
                    str(e["robot"]),
                    int(e["iteration"]),
                    f"{m}@{e['arena']}",
                    float(e[m]),
                )


def write_tidy(path: str | Path, rows: Iterable[Row]) -> int:
    """Write the rows under :data:`COLUMNS`; return how many were written."""
    n = 0
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for row in rows:
            w.writerow(row)
            n += 1
    return n
