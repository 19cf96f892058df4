"""Unit tests of the results-folder code (no processes): log facts, share matching, CSVs."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.config import ExperimentConfig, NodeConfig, RobotSpec, boundaries
from dfrl.experiments.results import (Fact, RoundRecord, Share, AgentLog, match_shares, merge_metrics,
                                 parse_fact, read_metrics, read_rounds_log, write_rounds_csv)
from dfrl.experiments.robot_node import table_digest


def test_parse_round_fact() -> None:
    t = parse_fact("round(3, 1700000000.25, 1700000000.5, 8, 24300, 'my method', [r1, r2]).")
    assert t == Fact("round", (3, 1700000000.25, 1700000000.5, 8, 24300, "my method", ["r1", "r2"]))
    assert parse_fact("finished(16).") == Fact("finished", (16,))
    assert parse_fact("x([], -2, 1.0Inf, \"s\")") == Fact("x", ([], -2, float("inf"), "s"))


def test_read_rounds_log(tmp_path: Path) -> None:
    log = tmp_path / "rounds.log"
    log.write_text("round(1, 10.0, 10.5, 2, 4860, average, [r1, r2]).\n"
                   "round(2, 11.0, 11.5, 2, 4860, median, [r1]).\n"
                   "garbage(\n"
                   "finished(2).\n", encoding="utf-8")
    got = read_rounds_log(log, "fed")
    assert [r.round for r in got.rounds] == [1, 2]
    assert got.rounds[1] == RoundRecord("fed", 2, 11.0, 11.5, 2, 4860, "median", ("r1",))
    assert got.finished == 2
    assert got.unreadable == ["garbage("]
    assert read_rounds_log(tmp_path / "missing.log", "fed").rounds == []


def test_match_shares_picks_the_share_inside_the_round() -> None:
    rec = RoundRecord("fed", 2, 10.0, 11.0, 2, 0, "average", ("r1", "r2"))
    shares = {
        "r1": [Share("r1", 1, 50, 9.99, "a"), Share("r1", 2, 100, 10.9, "b"),
               Share("r1", 3, 150, 11.2, "c")],
        "r2": [Share("r2", 1, 50, 9.5, "a")],
    }
    got = match_shares(rec, shares)
    assert got["r1"].digest == "b"
    assert got["r2"] is None


def test_write_rounds_csv_all_equal(tmp_path: Path) -> None:
    log = AgentLog("fed", [RoundRecord("fed", 1, 1.0, 2.0, 2, 10, "average", ("r1", "r2")),
                           RoundRecord("fed", 2, 3.0, 4.0, 2, 10, "average", ("r1", "r2"))])
    shares = {"r1": [Share("r1", 1, 5, 1.5, "x"), Share("r1", 2, 10, 3.5, "y")],
              "r2": [Share("r2", 1, 5, 1.4, "x"), Share("r2", 2, 10, 3.4, "z")]}
    rows = write_rounds_csv(tmp_path / "rounds.csv", [log], ["r1", "r2", "r3"], shares)
    assert [r["all_equal"] for r in rows] == [True, False]
    with open(tmp_path / "rounds.csv", newline="") as fh:
        written = list(csv.DictReader(fh))
    assert written[0]["digest_r1"] == written[0]["digest_r2"] == "x"
    assert written[0]["digest_r3"] == ""
    assert written[1]["all_equal"] == "false"


def test_merge_and_read_metrics(tmp_path: Path) -> None:
    for robot in ("r1", "r2"):
        (tmp_path / f"metrics_{robot}.csv").write_text(
            "robot,iteration,q_sum,cumulative_reward,collisions\n"
            f"{robot},1,0.5,1.0,0\n{robot},2,0.75,2.0,1\n{robot},3,0.", encoding="utf-8")
    merge_metrics(tmp_path, ["r1", "r2", "r9"])
    curves = read_metrics(tmp_path / "metrics.csv")
    assert list(curves) == ["r1", "r2"]
    assert curves["r2"]["q_sum"].tolist() == [0.5, 0.75]       # torn last line dropped
    assert curves["r1"]["collisions"].tolist() == [0, 1]


def test_boundaries_and_digest() -> None:
    assert boundaries(1200, 500) == [500, 1000, 1200]
    assert boundaries(1000, 500) == [500, 1000]
    assert boundaries(300, 500) == [300]
    q = np.arange(6, dtype=np.float64).reshape(3, 2)
    assert table_digest(q) == table_digest(q.copy()) != table_digest(q + 1e-12)
    assert len(table_digest(q)) == 64


def test_configs_round_trip_and_validate() -> None:
    n = NodeConfig(robot="r1", out_dir="/tmp/x", mode="sync", rtf=1.0)
    assert NodeConfig.from_dict(n.to_dict()) == n
    with pytest.raises(ValueError):
        NodeConfig.from_dict({"robot": "r1", "out_dir": "x", "colour": 1})
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
    from dfrl.experiments.config import CONFIGS_DIR

    names = sorted(p.stem for p in CONFIGS_DIR.glob("*.json"))
    assert {"demo", "paper_qlearning_average", "paper_qlearning_max", "paper_sarsa_average",
            "paper_sarsa_max", "hetero", "join"} <= set(names)
    for p in CONFIGS_DIR.glob("*.json"):
        ExperimentConfig.load(p)
