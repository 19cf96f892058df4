"""Curve statistics on hand-computed curves, and the figures of a tiny results folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.driver.results.plots import plot_experiment, robot_label
from dfrl.experiments.science.curves import dip, late_growth, reward_rate, smooth


def test_smooth_is_a_moving_average_with_a_short_start() -> None:
    assert smooth(np.array([2.0, 4.0, 6.0, 8.0]), window=2).tolist() == [2.0, 3.0, 5.0, 7.0]


def test_dip_late_growth_and_reward_rate_by_hand() -> None:
    # running means (window 100 > length): 4, 4, 8/3, 2; peak 4: drops 0, 0, 1/3, 1/2
    d, k = dip(np.array([4.0, 4.0, 0.0, 0.0]))
    assert (d, k) == (pytest.approx(0.5), 3)
    assert reward_rate(np.array([1.0, 2.0, 3.0, 4.0]), "first") == 1.0
    assert reward_rate(np.array([1.0, 2.0, 3.0, 10.0]), "last") == 7.0
    assert np.isnan(late_growth(np.array([1.0, 1.0, 1.0, 1.0])))


def test_plot_experiment_draws_three_figures(tmp_path: Path) -> None:
    rows = ["robot,iteration,q_sum,cumulative_reward,collisions"]
    rows += [f"{r},{i},{0.1 * i},{0.5 * i},0" for r in ("r1", "r2") for i in range(1, 51)]
    (tmp_path / "metrics.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    paths = plot_experiment(tmp_path, title="tiny")
    assert [p.name for p in paths] == ["q_sum.png", "cumulative_reward.png", "curves.png"]
    assert all(p.stat().st_size > 5_000 for p in paths)
    assert robot_label("r2", {"r2": "r4"}) == "R2 (R4)" and robot_label("r1", {"r1": "r1"}) == "R1"
