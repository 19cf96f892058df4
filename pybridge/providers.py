"""What a robot offers the bridge (:class:`TableProvider`), and a table without a robot.

The bridge validates a table write once, where it enters Python (shape, size, finite
values; see :mod:`dfrl.pybridge.serving`), so a provider's ``set_q_table`` always receives a
float64 array of the registered shape with finite entries.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["TableProvider", "StaticTable"]


@runtime_checkable
class TableProvider(Protocol):
    """What a robot offers to the bridge.

    ``q_table`` : float64 ndarray, shape (n_states, n_actions)
    ``visits`` : int64 ndarray, shape (n_states, n_actions)
    ``set_q_table(table)`` : replace the table with a float64 array of the same shape
    (already validated by the bridge: registered shape, finite entries)
    """

    @property
    def q_table(self) -> np.ndarray: ...

    @property
    def visits(self) -> np.ndarray: ...

    def set_q_table(self, table: np.ndarray) -> None: ...


class StaticTable:
    """A table provider without a robot: a random Q-table that only agents change.

    For benchmarks and tests. The same shape and seed give the same tables.

    Parameters
    ----------
    shape : (int, int)
        (n_states, n_actions), both positive.
    seed : int
        Seeds the Q-values (standard normal) and the visit counts (integers in [0, 100)).

    Attributes
    ----------
    sets : int
        How many times :meth:`set_q_table` replaced the table.
    """

    def __init__(self, shape: tuple[int, int], seed: int = 0) -> None:
        n_states, n_actions = (int(x) for x in shape)
        if n_states < 1 or n_actions < 1:
            raise ValueError(f"a table shape is two positive integers, got {tuple(shape)}")
        rng = np.random.default_rng(seed)
        self._q = rng.standard_normal((n_states, n_actions))
        self._visits = rng.integers(0, 100, (n_states, n_actions), dtype=np.int64)
        self.sets = 0

    @property
    def shape(self) -> tuple[int, int]:
        """(n_states, n_actions)."""
        return (int(self._q.shape[0]), int(self._q.shape[1]))

    @property
    def q_table(self) -> np.ndarray:
        """A copy of the Q-table, float64, shape (n_states, n_actions)."""
        return self._q.copy()

    @property
    def visits(self) -> np.ndarray:
        """A copy of the visit counts, int64, shape (n_states, n_actions)."""
        return self._visits.copy()

    def set_q_table(self, table: np.ndarray) -> None:
        """Replace the Q-table with a float64 copy of ``table`` (shape (n_states, n_actions))."""
        self._q = np.array(table, dtype=np.float64)
        self.sets += 1

    def __repr__(self) -> str:
        return f"<StaticTable shape={self.shape} sets={self.sets}>"
