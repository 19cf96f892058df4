"""Function learners in a federated run (real processes): the agent carries parameter vectors
and writes the same FedAvg back into every robot, reproducibly in sync mode."""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.driver.launcher import run
from dfrl.experiments.driver.results.metrics import read_metrics
from dfrl.experiments.processes import find_swipl
from dfrl.experiments.robot_host import table_digest
from dfrl.experiments.robot_host.checkpoint import load_checkpoint

from .helpers import diagnose, rounds_csv, small_config

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

#: dqn learns from its 64th transition on (default 500), in minibatches of 16, so that every
#: round of a 300-iteration run federates networks that moved
_DQN = {"dqn": {"learning_starts": 64, "batch_size": 16}}


def _shares(out: Path, robot: str) -> list[dict[str, str]]:
    with open(out / f"shares_{robot}.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _dqn_config():
    robots = (RobotSpec("r1", "r1", "dqn"), RobotSpec("r2", "r4", "dqn"))
    return small_config(robots=robots, iterations=300, respite=100, trainer=_DQN)


def _assert_federated(out: Path, agent: str, rounds: int, robots: tuple[str, ...]) -> list[str]:
    """Every round: every robot wrote the same parameter digest (rounds.csv and the shares
    files agree); the final params/ files equal the last round's aggregate. Returns the
    per-round digests."""
    rows = rounds_csv(out)
    assert [int(r["round"]) for r in rows] == list(range(1, rounds + 1))
    assert all(r["agent"] == agent and r["method"] == "average" for r in rows)
    digests = []
    for r in rows:
        assert r["all_equal"] == "true", r
        assert len({r[f"digest_{rid}"] for rid in robots}) == 1
        digests.append(r[f"digest_{robots[0]}"])
    for rid in robots:
        shares = _shares(out, rid)
        assert [s["digest"] for s in shares] == digests
        assert [s["round"] for s in shares] == [str(k) for k in range(1, rounds + 1)]
        final = np.load(out / "params" / f"{rid}.npy")
        assert final.ndim == 1 and table_digest(final) == digests[-1]
        side = json.loads((out / "params" / f"{rid}.json").read_text())
        assert side["format"] == "dfrl-params/2"
        cp = load_checkpoint(out / "checkpoint", rid)
        assert cp.q is None and table_digest(cp.params) == digests[-1]
        assert (out / "params" / "history" / f"{rid}_it{cp.iteration}.npy").is_file()
        # metrics.csv: a row per iteration, the shares marked, its q_sum the parameters' sum
        # after each write (the last: the saved parameters')
        cur = read_metrics(out / "metrics.csv")[rid]
        assert len(set(cur["iteration"].tolist())) == len(cur)
        assert cur["iteration"][cur["shared"] > 0].tolist() == [int(s["iteration"]) for s in shares]
        assert cur["q_sum"][cur["shared"] > 0].tolist() == [float(s["q_sum"]) for s in shares]
        assert cur["q_sum"][-1] == float(final.sum())
    assert not (out / "tables").exists()
    launch = json.loads((out / f"launch_{agent}.json").read_text())
    assert launch["carries"] == "params"
    return digests


def test_dqn_federation_same_parameters_every_round_and_reproducible(tmp_path: Path) -> None:
    # Prepare: 2 dqn robots, sync, 3 rounds of FedAvg
    cfg = _dqn_config()
    # Execute: the same config and seed twice
    t0 = time.monotonic()
    res = run(cfg, tmp_path / "a", progress=None)
    wall = time.monotonic() - t0
    assert res.ok, (res.crashed, res.agents_finished)
    run(cfg, tmp_path / "b", progress=None)
    # Assert: same parameters in every robot after every share, the networks moved between
    # rounds, and the second run is the first one bit for bit
    da = _assert_federated(tmp_path / "a", "fed_dqn", 3, ("r1", "r2"))
    db = _assert_federated(tmp_path / "b", "fed_dqn", 3, ("r1", "r2"))
    assert len(set(da)) == 3
    assert da == db
    same = (tmp_path / "a/metrics.csv").read_bytes() == (tmp_path / "b/metrics.csv").read_bytes()
    assert same, diagnose(tmp_path / "a", tmp_path / "b")
    summary = (tmp_path / "a" / "summary.md").read_text()
    assert "3/3" in summary and "(sum of parameters, params/)" in summary
    final = float(np.load(tmp_path / "a" / "params" / "r1.npy").sum())
    assert f"| {final:.2f} (sum of parameters, params/) |" in summary
    print(f"tiny dqn run: {wall:.1f} s wall")


def test_linear_federation_with_live_evaluations(tmp_path: Path) -> None:
    robots = (RobotSpec("r1", "r1", "linear"), RobotSpec("r2", "r4", "linear"))
    cfg = small_config(robots=robots, iterations=200, respite=50, eval_every=100, eval_steps=50)
    res = run(cfg, tmp_path, progress=None)
    assert res.ok, (res.crashed, res.agents_finished)
    digests = _assert_federated(tmp_path, "fed_linear", 4, ("r1", "r2"))
    assert len(set(digests)) == 4
    assert np.load(tmp_path / "params" / "r1.npy").shape == (771,)
    # the greedy policy of the (just federated) parameters, measured every 100 iterations
    for rid in ("r1", "r2"):
        with open(tmp_path / f"eval_{rid}.csv", newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
        assert [int(r["iteration"]) for r in rows] == [100, 200]
        assert all(int(r["steps"]) == 50 for r in rows)
    assert (
        "last greedy evaluation (iteration 200, 50 steps)" in (tmp_path / "summary.md").read_text()
    )


def test_tabular_and_dqn_side_by_side(tmp_path: Path) -> None:
    # one agent per algorithm: max over the Q-tables, FedAvg over the networks
    robots = (
        RobotSpec("r1", "r1", "qlearning"),
        RobotSpec("r2", "r4", "dqn"),
        RobotSpec("r3", "r2", "dqn"),
        RobotSpec("r4", "r3", "qlearning"),
    )
    cfg = small_config(
        robots=robots,
        iterations=200,
        respite=100,
        method="max",
        methods={"dqn": "average"},
        trainer=_DQN,
    )
    res = run(cfg, tmp_path, progress=None)
    assert res.ok and res.agents_finished == {"fed_qlearning": 2, "fed_dqn": 2}
    rows = rounds_csv(tmp_path)
    assert {(r["agent"], r["method"], r["visited"]) for r in rows} == {
        ("fed_qlearning", "max", "r1 r4"),
        ("fed_dqn", "average", "r2 r3"),
    }
    assert all(r["all_equal"] == "true" for r in rows)
    assert sorted(p.name for p in (tmp_path / "tables").glob("*.npy")) == [
        "r1.npy",
        "r1.visits.npy",
        "r4.npy",
        "r4.visits.npy",
    ]
    assert sorted(p.name for p in (tmp_path / "params").glob("*.npy")) == ["r2.npy", "r3.npy"]
    assert "carries" not in json.loads((tmp_path / "launch_fed_qlearning.json").read_text())
