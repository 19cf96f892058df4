"""The robot node's result files: ``metrics_<robot>.csv`` and ``shares_<robot>.csv``."""
from __future__ import annotations

import csv
import hashlib
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["METRIC_FIELDS", "SHARE_FIELDS", "table_digest", "CsvLog"]

METRIC_FIELDS: tuple[str, ...] = ("robot", "iteration", "q_sum", "cumulative_reward", "collisions")
SHARE_FIELDS: tuple[str, ...] = ("robot", "share_index", "iteration", "wall_time", "digest")


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
    """

    def __init__(self, path: Path, fields: tuple[str, ...]) -> None:
        self._fh = open(path, "w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._fh)
        self._writer.writerow(fields)
        self._fh.flush()

    def row(self, values: tuple[Any, ...] | list[Any], flush: bool = False) -> None:
        """Append one row (flushed at once with ``flush=True``)."""
        self._writer.writerow(values)
        if flush:
            self._fh.flush()

    def flush(self) -> None:
        """Flush what was written."""
        self._fh.flush()

    def close(self) -> None:
        """Close the file (idempotent)."""
        if not self._fh.closed:
            self._fh.close()


def share_row(robot: str, share_index: int, iteration: int, table: np.ndarray) -> tuple[Any, ...]:
    """A ``shares_<robot>.csv`` row for a table just set (wall time: now)."""
    return (robot, share_index, iteration, repr(time.time()), table_digest(table))
