"""What one training iteration reports (:class:`StepMetrics`) and the ``metrics.csv`` files.

Imported by :mod:`dfrl.robots.training`, where callers usually take them from.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True, slots=True)
class StepMetrics:
    """What happened in one iteration.

    Attributes
    ----------
    iteration : int
        1-based count of control steps so far.
    q_sum : float
        Sum of all Q-table entries after the update (function-approximation learners: sum of
        the parameter vector, a drift indicator only).
    cumulative_reward : float
        Sum of rewards over iterations ``1 .. iteration``.
    collisions : int
        Collisions so far (cumulative).
    reward : float
        This step's reward.
    collided : bool
        This step ended in a collision.
    respawns : int
        Respawns so far (collisions with RESPAWN, and stuck detections).
    epsilon : float
        Exploration probability used for the next action.
    state, action : int
        State and action of the updated entry (function learners: the discretised state of
        the observation they learnt from, for the record).
    x, y : float
        Robot position after the step (m).
    """

    iteration: int
    q_sum: float
    cumulative_reward: float
    collisions: int
    reward: float
    collided: bool
    respawns: int
    epsilon: float
    state: int
    action: int
    x: float
    y: float

    FIELDS = (
        "iteration",
        "q_sum",
        "cumulative_reward",
        "collisions",
        "reward",
        "collided",
        "respawns",
        "epsilon",
        "state",
        "action",
        "x",
        "y",
    )

    def as_row(self) -> tuple[Any, ...]:
        """Values in :attr:`FIELDS` order."""
        return tuple(getattr(self, f) for f in self.FIELDS)


#: One record per iteration, the fields of :class:`StepMetrics`.
METRIC_DTYPE = np.dtype(
    [
        ("iteration", np.int64),
        ("q_sum", np.float64),
        ("cumulative_reward", np.float64),
        ("collisions", np.int64),
        ("reward", np.float64),
        ("collided", np.bool_),
        ("respawns", np.int64),
        ("epsilon", np.float64),
        ("state", np.int64),
        ("action", np.int64),
        ("x", np.float64),
        ("y", np.float64),
    ]
)


def write_metrics_csv(path: str | Path, metrics: np.ndarray) -> None:
    """Write a metrics record array as CSV with a header row."""
    names = metrics.dtype.names or ()
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(names)
        for rec in metrics.tolist():
            writer.writerow(
                [
                    int(v) if isinstance(v, bool) else (repr(v) if isinstance(v, float) else v)
                    for v in rec
                ]
            )


def read_metrics_csv(path: str | Path) -> np.ndarray:
    """Read a ``metrics.csv`` back into a structured array."""
    data = np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    return np.atleast_1d(data)
