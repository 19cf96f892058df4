"""Discretisation of the IR proximities into a tabular state index.

The 8 sensors are grouped (a :class:`SensorGrouping`); each group's value is the largest
proximity ``p = 1 - d / range`` among its sensors; that value is quantised into ``levels``
levels:

* level 0: nothing in range (``p == 0``);
* level ``k`` in ``1 .. levels-1``: ``(k-1)/(levels-1) < p <= k/(levels-1)``,
  i.e. the sensing range is split evenly and level ``levels-1`` is the closest band.

The state index is the mixed-radix number ``sum_g level_g * levels**g`` (group 0 is the least
significant digit), so ``n_states = levels ** n_groups``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from enum import Enum
from typing import Any

import numpy as np


class SensorGrouping(str, Enum):
    """Which sensors form each state group (indices of ``ps0`` ... ``ps7``).

    The rear sensors ``ps3``/``ps4`` are left out by the groupings below EIGHT: the robot
    never drives backwards.
    """

    THREE = "three"  #: right (ps1, ps2), front (ps0, ps7), left (ps5, ps6)
    FOUR = "four"  #: right (ps2), front-right (ps0, ps1), front-left (ps6, ps7), left (ps5)
    FIVE = "five"  #: right (ps2), front-right (ps1), front (ps0, ps7), front-left (ps6), left (ps5)
    SIX = "six"  #: each of ps2, ps1, ps0, ps7, ps6, ps5
    EIGHT = "eight"  #: each sensor on its own

    @property
    def groups(self) -> tuple[tuple[int, ...], ...]:
        """Sensor indices of each group."""
        return {
            SensorGrouping.THREE: ((1, 2), (0, 7), (5, 6)),
            SensorGrouping.FOUR: ((2,), (0, 1), (6, 7), (5,)),
            SensorGrouping.FIVE: ((2,), (1,), (0, 7), (6,), (5,)),
            SensorGrouping.SIX: ((2,), (1,), (0,), (7,), (6,), (5,)),
            SensorGrouping.EIGHT: tuple((i,) for i in range(8)),
        }[self]


@dataclass(frozen=True)
class DiscretisationConfig:
    """State discretisation parameters.

    Attributes
    ----------
    grouping : SensorGrouping
        How sensors are grouped.
    levels : int
        Quantisation levels per group (>= 2).

    Examples
    --------
    THREE x 3 levels: 27 states (81 entries with 3 actions); FOUR x 3: 81 states (the
    default, 243 entries); FIVE x 3: 243 states (729 entries); EIGHT x 3: 6,561 states
    (19,683 entries).
    """

    grouping: SensorGrouping = SensorGrouping.FOUR
    levels: int = 3

    def __post_init__(self) -> None:
        object.__setattr__(self, "grouping", SensorGrouping(self.grouping))
        if int(self.levels) != self.levels or self.levels < 2:
            raise ValueError(
                f"DiscretisationConfig.levels must be an integer >= 2, got {self.levels}"
            )

    @property
    def n_states(self) -> int:
        """Number of discrete states."""
        return int(self.levels) ** len(self.grouping.groups)


class Discretiser:
    """Maps proximity vectors to state indices.

    Parameters
    ----------
    config : DiscretisationConfig
        Grouping and resolution.
    """

    def __init__(self, config: DiscretisationConfig | None = None) -> None:
        self.config = config or DiscretisationConfig()
        self.groups = self.config.grouping.groups
        self.levels = int(self.config.levels)
        self.n_states = self.config.n_states
        self._radix = [self.levels**g for g in range(len(self.groups))]

    def levels_of(self, proximity: np.ndarray) -> list[int]:
        """Quantised level of each group.

        Parameters
        ----------
        proximity : np.ndarray, shape (8,)
            Proximities in ``[0, 1]``.

        Returns
        -------
        list[int]
            One level in ``0 .. levels-1`` per group.
        """
        top = self.levels - 1
        prox = proximity.tolist() if isinstance(proximity, np.ndarray) else list(proximity)
        out = []
        for group in self.groups:
            value = max([prox[i] for i in group])
            level = math.ceil(value * top) if value > 0.0 else 0
            out.append(min(level, top))
        return out

    def __call__(self, proximity: np.ndarray) -> int:
        """State index of a proximity vector (see the module docstring)."""
        return sum(lv * r for lv, r in zip(self.levels_of(proximity), self._radix))

    def describe(self) -> dict[str, Any]:
        """A JSON-ready description, saved beside Q-tables."""
        return {
            "kind": "grouped_max_proximity",
            "grouping": self.config.grouping.value,
            "groups": [list(g) for g in self.groups],
            "levels": self.levels,
            "n_states": self.n_states,
            "encoding": "state = sum_g level_g * levels**g; level 0 = nothing in range, "
            "level k = proximity in ((k-1)/(levels-1), k/(levels-1)]; "
            "proximity = 1 - distance / sensor_range; "
            "group value = max over its sensors",
        }
