"""The end-of-run files of a hand-made results folder (no processes): robots that ended short
of their iterations are named, a robot that joined through ``dfrl join`` (in no config) gets
its arena and algorithm from ``nodes.json``, the history verdict is in ``summary.md``."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.results.agent_log import AgentLog, RoundRecord
from dfrl.experiments.driver.results.ending import RunFacts, ended_short, write_end_files
from dfrl.experiments.driver.results.files import write_json
from dfrl.experiments.driver.results.summary import robot_kinds
from dfrl.experiments.robot_host.files import (METRIC_FIELDS, SHARE_FIELDS, CsvLog,
                                               share_row)

AGENT = "fed_qlearning"


def make_folder(out: Path) -> tuple[ExperimentConfig, AgentLog]:
    """r1 and r2 of the config (200 iterations; r2 stopped at 150), r3 joined by
    ``dfrl join`` for 100 iterations and ran them all; 2 rounds, every robot written."""
    config = ExperimentConfig(name="t", robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4")),
                              iterations=200, respite=100)
    ran = {"r1": 200, "r2": 150, "r3": 100}
    for rid, last in ran.items():
        metrics = CsvLog(out / f"metrics_{rid}.csv", METRIC_FIELDS)
        for it in range(1, last + 1):
            metrics.row((rid, it, 1.0, 0.5 * it, 0))
        metrics.close()
        shares = CsvLog(out / f"shares_{rid}.csv", SHARE_FIELDS)
        for n in (1, 2):
            shares.row(share_row(rid, n, 50 * n, np.full((2, 2), float(n)),
                                 {"round": n, "agent": AGENT, "epoch": 1}))
        shares.close()
    write_json(out / "nodes.json", {"nodes": [
        {"robot": "r1", "arena": "r1", "algo": "qlearning"},
        {"robot": "r2", "arena": "r4", "algo": "qlearning"},
        {"robot": "r3", "arena": "r5", "algo": "qlearning", "joined": True}], "agents": []})
    write_json(out / "nodes" / "r3.json", {"robot": "r3", "arena": "r5", "algo": "qlearning",
                                           "iterations": 100})
    rounds = [RoundRecord(AGENT, n, float(n), n + 0.5, 3, 10, "average", ("r1", "r2", "r3"))
              for n in (1, 2)]
    return config, AgentLog(AGENT, rounds, finished=2)


def test_ended_short_compares_the_last_iteration_with_the_robots_plan(tmp_path: Path) -> None:
    config, _ = make_folder(tmp_path)
    from dfrl.experiments.driver.results.metrics import merge_metrics

    merge_metrics(tmp_path, ["r1", "r2", "r3"])
    assert ended_short(tmp_path, config, ["r1", "r2", "r3"], {}) == \
        {"r2": "ended at iteration 150 of 200"}
    # without metrics: what the writer knew; a robot of unknown plan is not judged
    (tmp_path / "metrics.csv").unlink()
    assert ended_short(tmp_path, config, ["r1", "r2", "r3", "r9"],
                       {"r1": 120, "r9": 1}) == {"r1": "ended at iteration 120 of 200"}


def test_a_joined_robot_has_its_arena_and_algo(tmp_path: Path) -> None:
    config, _ = make_folder(tmp_path)
    assert robot_kinds(tmp_path, config) == {"r1": ("r1", "qlearning"),
                                             "r2": ("r4", "qlearning"),
                                             "r3": ("r5", "qlearning")}


def test_the_summary_names_the_short_robot_the_joiner_and_the_history(tmp_path: Path) -> None:
    config, log = make_folder(tmp_path)
    res = write_end_files(tmp_path, config, ["r1", "r2", "r3"], {AGENT: log}, {AGENT: 2},
                          RunFacts(1.0, finished=["r1", "r3"]), lambda line: None)
    summary = (tmp_path / "summary.md").read_text(encoding="utf-8")
    assert "| r3 | r5 | qlearning | 100 |" in summary
    assert "- ENDED SHORT: r2 ended at iteration 150 of 200" in summary
    assert "## History: ok" in summary and "6 write(s) of 1 agent(s) in 2 round(s)" in summary
    assert res.history is not None and res.history.ok
