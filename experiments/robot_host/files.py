"""The robot process's result files: ``metrics_<robot>.csv`` and ``shares_<robot>.csv``."""

from __future__ import annotations

import csv
import hashlib
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["METRIC_FIELDS", "SHARE_FIELDS", "ORIGIN_FIELDS", "table_digest", "CsvLog", "share_row"]

METRIC_FIELDS: tuple[str, ...] = ("robot", "iteration", "q_sum", "cumulative_reward", "collisions")
SHARE_FIELDS: tuple[str, ...] = (
    "robot",
    "share_index",
    "iteration",
    "wall_time",
    "digest",
    "round",
    "agent",
    "epoch",
    "q_sum",
)
#: The options of an agent's table write recorded with each share (contract K4).
ORIGIN_FIELDS: tuple[str, ...] = ("round", "agent", "epoch")


def table_digest(table: np.ndarray) -> str:
    """sha256 (hex) of a table's float64 bytes in row-major order."""
    arr = np.ascontiguousarray(table, dtype=np.float64)
    return hashlib.sha256(arr.tobytes()).hexdigest()


class CsvLog:
    """One CSV file with a header row, written row by row.

    Parameters
    ----------
    path : Path
    fields : tuple of str
        The header.
    keep : callable, optional
        Resume an existing file: its rows (as dicts) for which ``keep(row)`` is true are
        written back first, in order (a torn last row is dropped); without it, or without a
        file, a new file is started.
    """

    def __init__(
        self,
        path: Path,
        fields: tuple[str, ...],
        keep: Callable[[dict[str, str]], bool] | None = None,
    ) -> None:
        kept: list[list[str]] = []
        if keep is not None and path.is_file():
            with open(path, newline="", encoding="utf-8") as fh:
                for row in csv.DictReader(fh):
                    if None in row.values() or None in row:
                        continue  # torn (too short or too long)
                    try:
                        if keep(row):
                            kept.append([row.get(f, "") for f in fields])
                    except (TypeError, ValueError):
                        continue
        self._fh = open(path, "w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._fh)
        self._writer.writerow(fields)
        self._writer.writerows(kept)
        self._fh.flush()

    def row(self, values: tuple[Any, ...] | list[Any], flush: bool = False) -> None:
        """Append one row (flushed at once with ``flush=True``)."""
        self._writer.writerow(values)
        if flush:
            self._fh.flush()

    def flush(self) -> None:
        """Flush what was written."""
        self._fh.flush()

    def sync(self) -> None:
        """Flush and fsync (the rows survive a crash of the process or the machine)."""
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        """Close the file (idempotent)."""
        if not self._fh.closed:
            self._fh.close()


def share_row(
    robot: str,
    share_index: int,
    iteration: int,
    table: np.ndarray,
    origin: Mapping[str, Any] | None = None,
    q_sum: float | None = None,
) -> tuple[Any, ...]:
    """A ``shares_<robot>.csv`` row for a table just set (wall time: now); ``origin`` holds
    the write's ``round``, ``agent`` and ``epoch`` (each empty when absent); ``q_sum`` the sum
    the write left, as the robot's metrics measure it (the table's sum; a function learner's:
    its parameters'), empty when not given."""
    origin = origin or {}
    extra = tuple("" if origin.get(f) is None else origin[f] for f in ORIGIN_FIELDS)
    return (
        (robot, share_index, iteration, repr(time.time()), table_digest(table))
        + extra
        + ("" if q_sum is None else repr(float(q_sum)),)
    )
