"""What a robot records about the shares beyond ``shares_<robot>.csv``: how well a grid write
was distilled, and the weight its parameters had in a FedAvg read.

Two files in the robot's folder, each started on its first row (a robot that never distils,
or is never read as parameters, writes neither) and appended to afterwards (a robot resumed
from a checkpoint keeps the rows of the writes it had done; the driver reads them by round):

``distillation_<robot>.csv`` (:data:`DISTILLATION_FIELDS`)
    One row per table write a function learner absorbed by distillation (a grid federation's
    write to a ``linear`` or ``dqn`` robot, :class:`dfrl.robots.grid_view.GridView`): the
    write's round, agent and epoch, the robot's iteration, the Adam steps taken, the root mean
    squared residual ``Q(x_b, a) - T[b, a]`` over the grid before and after, the largest
    absolute residual after, and the seconds it took (:class:`dfrl.robots.distill.DistilReport`).
``weights_<robot>.csv`` (:data:`WEIGHT_FIELDS`)
    One row per read of the robot's parameters by an agent: the iteration, the wall time and
    the samples (the transitions the learner learnt from) it reported: its weight in the
    agent's FedAvg. A read names no round; the driver matches a round's write to the last
    read before it (:mod:`dfrl.experiments.driver.results.carried`).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TextIO

__all__ = ["DISTILLATION_FIELDS", "WEIGHT_FIELDS", "ShareNotes"]

DISTILLATION_FIELDS: tuple[str, ...] = (
    "robot",
    "round",
    "agent",
    "epoch",
    "iteration",
    "steps",
    "rms_before",
    "rms_after",
    "max_after",
    "seconds",
)
WEIGHT_FIELDS: tuple[str, ...] = ("robot", "iteration", "wall_time", "samples")


class _Appender:
    """One CSV file opened for appending on its first row (with a header when new)."""

    def __init__(self, path: Path, fields: tuple[str, ...]) -> None:
        self.path = path
        self.fields = fields
        self._fh: TextIO | None = None

    def row(self, values: tuple[Any, ...]) -> None:
        if self._fh is None:
            new = not self.path.is_file() or self.path.stat().st_size == 0
            self._fh = open(self.path, "a", newline="", encoding="utf-8")
            if new:
                csv.writer(self._fh).writerow(self.fields)
        csv.writer(self._fh).writerow(values)
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None and not self._fh.closed:
            self._fh.close()


class ShareNotes:
    """The two files of the module doc for robot ``robot`` in folder ``out_dir``."""

    def __init__(self, out_dir: Path, robot: str) -> None:
        self.robot = robot
        self._distilled = _Appender(
            Path(out_dir) / f"distillation_{robot}.csv", DISTILLATION_FIELDS
        )
        self._weights = _Appender(Path(out_dir) / f"weights_{robot}.csv", WEIGHT_FIELDS)

    def write_distillation(self, iteration: int, origin: Mapping[str, Any], report: Any) -> None:
        """Append the row of a write absorbed by distillation (``report``: a
        :class:`dfrl.robots.distill.DistilReport`; ``origin``: the write's ``round``,
        ``agent``, ``epoch``)."""
        got = tuple("" if origin.get(f) is None else origin[f] for f in ("round", "agent", "epoch"))
        self._distilled.row(
            (
                self.robot,
                *got,
                iteration,
                report.steps,
                repr(float(report.rms_before)),
                repr(float(report.rms_after)),
                repr(float(report.max_after)),
                repr(float(report.seconds)),
            )
        )

    def write_weight(self, iteration: int, samples: int) -> None:
        """Append the row of a read of the parameters that reported ``samples``."""
        self._weights.row((self.robot, iteration, repr(time.time()), int(samples)))

    def close(self) -> None:
        """Close both files (idempotent)."""
        self._distilled.close()
        self._weights.close()
