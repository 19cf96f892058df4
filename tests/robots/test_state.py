"""Discretisation: hand-computed indices and the table sizes it can reach."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.robots.state import DiscretisationConfig, Discretiser, SensorGrouping


def test_levels_by_hand() -> None:
    disc = Discretiser(DiscretisationConfig(SensorGrouping.THREE, 3))
    prox = np.zeros(8)
    assert disc(prox) == 0
    prox[1] = 0.3  # right group (ps1, ps2): level ceil(0.3 * 2) = 1
    prox[7] = 0.9  # front group (ps0, ps7): level 2
    prox[5] = 0.5  # left group (ps5, ps6): level ceil(1.0) = 1
    assert disc.levels_of(prox) == [1, 2, 1]
    assert disc(prox) == 1 + 2 * 3 + 1 * 9
    prox[:] = 1.0
    assert disc(prox) == disc.n_states - 1


@pytest.mark.parametrize(
    "grouping, levels, n_actions, entries",
    [
        ("three", 3, 3, 81),  # about 100 entries
        ("four", 3, 3, 243),  # the default
        ("five", 3, 3, 729),
        ("eight", 3, 3, 19_683),  # about 20,000 entries
    ],
)
def test_table_sizes(grouping: str, levels: int, n_actions: int, entries: int) -> None:
    disc = Discretiser(DiscretisationConfig(grouping, levels))
    assert disc.n_states * n_actions == entries
    rng = np.random.default_rng(0)
    states = {disc(rng.uniform(0, 1, 8) * (rng.uniform(size=8) < 0.5)) for _ in range(2000)}
    assert min(states) >= 0 and max(states) < disc.n_states


def test_bad_levels() -> None:
    with pytest.raises(ValueError, match="levels"):
        DiscretisationConfig("four", 1)
    with pytest.raises(ValueError):
        DiscretisationConfig("nine", 3)
