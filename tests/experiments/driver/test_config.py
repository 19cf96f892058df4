"""Experiment and node configurations: round trips, validation, shipped configs, boundaries."""
from __future__ import annotations

import numpy as np
import pytest

from dfrl.experiments.driver.config import ExperimentConfig, RobotConfig, RobotSpec, boundaries
from dfrl.experiments.robot_host import table_digest


def test_boundaries_and_digest() -> None:
    assert boundaries(1200, 500) == [500, 1000, 1200]
    assert boundaries(1000, 500) == [500, 1000]
    assert boundaries(300, 500) == [300]
    q = np.arange(6, dtype=np.float64).reshape(3, 2)
    assert table_digest(q) == table_digest(q.copy()) != table_digest(q + 1e-12)
    assert len(table_digest(q)) == 64


def test_configs_round_trip_and_validate() -> None:
    n = RobotConfig(robot="r1", out_dir="/tmp/x", mode="sync", rtf=1.0)
    assert RobotConfig.from_dict(n.to_dict()) == n
    with pytest.raises(ValueError):
        RobotConfig.from_dict({"robot": "r1", "out_dir": "x", "colour": 1})
    cfg = ExperimentConfig(robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4", "sarsa")),
                           iterations=1200, respite=500, methods={"sarsa": "max"})
    assert cfg.rounds == 3
    assert cfg.algorithms() == ["qlearning", "sarsa"]
    assert cfg.method_for("sarsa") == "max" and cfg.method_for("qlearning") == "average"
    assert [cfg.robot_seed(r) for r in cfg.robots] == [1, 2]
    assert ExperimentConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError):
        ExperimentConfig(robots=(RobotSpec("r1", "r1"), RobotSpec("r1", "r2")))
    with pytest.raises(ValueError):
        RobotSpec("R1", "r1")


def test_shipped_configs_load() -> None:
    from dfrl.experiments.driver.config import CONFIGS_DIR

    names = sorted(p.stem for p in CONFIGS_DIR.glob("*.json"))
    assert {"demo", "paper_qlearning_average", "paper_qlearning_max", "paper_sarsa_average",
            "paper_sarsa_max", "hetero", "join"} <= set(names)
    for p in CONFIGS_DIR.glob("*.json"):
        ExperimentConfig.load(p)
