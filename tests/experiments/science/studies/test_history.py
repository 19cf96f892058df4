"""Evaluation points, table history files, and determinism of an evaluated standalone run."""

import numpy as np

from dfrl.experiments.science.standalone import evaluated_job
from dfrl.experiments.science.studies.history import history_tables, pick, read_rows
from dfrl.robots.training import TrainerConfig


def test_pick_nearest_to_even_points():
    assert pick([500 * k for k in range(1, 41)], 20000, 4) == [5000, 10000, 15000, 20000]
    assert pick([300, 900], 1000, 4) == [300, 900]
    assert pick([], 100, 3) == []


def test_history_tables(tmp_path):
    d = tmp_path / "tables" / "history"
    d.mkdir(parents=True)
    for name in ("r1_it500.npy", "r1_it1000.npy", "r2_it500.npy"):
        np.save(d / name, np.zeros((2, 2)))
    h = history_tables(tmp_path)
    assert sorted(h) == ["r1", "r2"] and sorted(h["r1"]) == [500, 1000]


def test_evaluated_standalone_run_is_deterministic(tmp_path):
    cfg = TrainerConfig(arena="r1", seed=3, iterations=300).to_dict()
    rows = []
    for k in range(2):
        evaluated_job(cfg, str(tmp_path / str(k)), 2, ["h1"], 100, 50, 7)
        rows.append(read_rows(tmp_path / str(k) / "evaluations.csv"))
    assert rows[0] == rows[1]
    assert [(r["iteration"], r["arena"], r["role"]) for r in rows[0]] == [
        (150, "r1", "own"),
        (300, "r1", "own"),
        (300, "h1", "held_out"),
    ]  # held-out: the last
    assert all(r["steps"] == 100 for r in rows[0])
