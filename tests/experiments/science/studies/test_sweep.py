"""The sweep runs real training and evaluation; tiny budgets here."""

from __future__ import annotations

import pytest

from dfrl.experiments.science.studies.sweep import markdown_table, settings, sweep
from dfrl.robots.training import TrainerConfig


def _base() -> dict:
    return TrainerConfig(arena="r4", iterations=400).to_dict()


def test_settings_one_factor_at_a_time_and_grid() -> None:
    f = {"learner.alpha": [0.1, 0.4], "learner.gamma": [0.9]}
    assert [s.name for s in settings(f)] == [
        "base",
        "learner.alpha=0.1",
        "learner.alpha=0.4",
        "learner.gamma=0.9",
    ]
    assert [s.changes for s in settings(f, "grid")][1:] == [
        (("learner.alpha", 0.1), ("learner.gamma", 0.9)),
        (("learner.alpha", 0.4), ("learner.gamma", 0.9)),
    ]


def test_unknown_field_fails_before_any_run() -> None:
    with pytest.raises(KeyError, match="learner.alhpa"):
        sweep(_base(), {"learner.alhpa": [0.1]}, seeds=[1], jobs=1)


def test_tiny_sweep_is_deterministic_and_tabulated() -> None:
    f = {"learner.alpha": [0.5]}
    a = sweep(_base(), f, seeds=[1, 2], arenas=("h1",), eval_steps=150, stable_last=2, jobs=2)
    b = sweep(_base(), f, seeds=[1, 2], arenas=("h1",), eval_steps=150, stable_last=2, jobs=1)
    assert [r.setting.name for r in a] == ["base", "learner.alpha=0.5"]
    assert [r.runs for r in a] == [r.runs for r in b]
    assert a[0].runs != a[1].runs
    run = a[0].runs[0]
    assert run["states"] == 81 and 0 < run["states_visited"] <= 81
    assert -1.0 <= run["own_progress"] <= 1.0
    table = markdown_table(a)
    assert table.count("\n") == 3 and "learner.alpha=0.5" in table and "±" in table
