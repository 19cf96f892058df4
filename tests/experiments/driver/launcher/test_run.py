"""run(config, out) on real processes: robot nodes on loopback and the Prolog agent."""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.launcher import Results, run
from dfrl.experiments.driver.results.files import ClaimedFolder, claim_output
from dfrl.experiments.driver.results.metrics import read_metrics

from .helpers import diagnose, rounds_csv, run_in_thread, small_config, wait_rounds
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def test_two_robot_smoke_run(tmp_path: Path) -> None:
    cfg = small_config()
    res = run(cfg, tmp_path, progress=None)
    assert res.ok, (res.crashed, res.agents_finished)
    for name in (
        "config.json",
        "nodes.json",
        "metrics.csv",
        "rounds.csv",
        "summary.md",
        "q_sum.png",
        "cumulative_reward.png",
        "curves.png",
    ):
        assert (tmp_path / name).is_file(), name
    assert (tmp_path / "q_sum.png").stat().st_size > 10_000
    # config.json: the config resolved (every seed, every trainer setting), which runs the same
    assert (
        ExperimentConfig.from_dict(json.loads((tmp_path / "config.json").read_text()))
        == cfg.resolved()
    )
    nodes = json.loads((tmp_path / "nodes.json").read_text())
    assert [n["robot"] for n in nodes["nodes"]] == ["r1", "r2"]
    assert all(n["host"] == "127.0.0.1" and n["port"] > 0 for n in nodes["nodes"])
    curves = read_metrics(tmp_path / "metrics.csv")
    assert list(curves) == ["r1", "r2"]
    with open(tmp_path / "metrics.csv", newline="") as fh:
        keys = [(r["robot"], int(r["iteration"])) for r in csv.DictReader(fh)]
    assert len(keys) == len(set(keys)) == 400  # one row per robot and iteration
    summary = (tmp_path / "summary.md").read_text()
    for rid, cur in curves.items():
        assert cur["iteration"].tolist() == list(range(1, 201))
        # the shares file's writes are the rows marked shared; such a row holds the sum the
        # write left, and the learner's from before it, as the robot's own file has it
        with open(tmp_path / f"shares_{rid}.csv", newline="") as fh:
            writes = list(csv.DictReader(fh))
        assert [int(w["iteration"]) for w in writes] == [50, 100, 150, 200]
        marked = cur["shared"] > 0
        assert cur["iteration"][marked].tolist() == [50, 100, 150, 200]
        assert set(cur["shared"].tolist()) == {0, 1}
        assert cur["q_sum"][marked].tolist() == [float(w["q_sum"]) for w in writes]
        own = read_metrics(tmp_path / f"metrics_{rid}.csv")[rid]
        assert np.array_equal(cur["q_sum_before_share"][marked], own["q_sum"][marked])
        assert np.array_equal(cur["q_sum"][~marked], own["q_sum"][~marked])
        assert np.isnan(cur["q_sum_before_share"][~marked]).all()
        assert (cur["q_sum"][marked] != own["q_sum"][marked]).all()  # the shares moved it
        assert cur["q_sum"][-1] > 0 and cur["cumulative_reward"][-1] > 0
        # numbers agree: the curve and the summary end with the saved table's sum
        table = np.load(tmp_path / "tables" / f"{rid}.npy")
        assert cur["q_sum"][-1] == pytest.approx(float(table.sum()), rel=1e-12)
        assert f"| {rid} | " in summary and f"| {float(table.sum()):.2f} |" in summary
    rows = rounds_csv(tmp_path)
    assert [int(r["round"]) for r in rows] == [1, 2, 3, 4]
    for r in rows:
        # right after each backward pass every robot holds the same table
        assert r["all_equal"] == "true"
        assert r["digest_r1"] == r["digest_r2"] and len(r["digest_r1"]) == 64
        assert r["visited"] == "r1 r2" and r["method"] == "average" and int(r["hops"]) == 2
        assert int(r["bytes"]) > 0 and float(r["end"]) > float(r["start"])
    assert len({r["digest_r1"] for r in rows}) == 4  # the tables moved on between rounds
    summary = (tmp_path / "summary.md").read_text()
    assert "4/4" in summary
    # after each share both robots hold the average: the same sum in their shared rows
    assert (
        curves["r1"]["q_sum"][curves["r1"]["shared"] > 0].tolist()
        == curves["r2"]["q_sum"][curves["r2"]["shared"] > 0].tolist()
    )


def test_output_folder_is_claimed_once(tmp_path: Path) -> None:
    # Prepare: a folder a caller claimed (as dfrl run does), which then got a file of its own
    # (the live view's, say); and one nobody claimed holding a foreign file
    claimed = ClaimedFolder(claim_output(tmp_path / "claimed"))
    (claimed.path / "view.log").write_text("mine")
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    # Execute and Assert: the claimed folder is used as it is, the other one is refused
    res = run(small_config(1), claimed, progress=None)
    assert res.ok and res.output_dir == claimed.path.resolve()
    assert (claimed.path / "view.log").read_text() == "mine"
    with pytest.raises(FileExistsError, match="is not empty"):
        run(small_config(1), foreign, progress=None)
    assert [p.name for p in foreign.iterdir()] == ["notes.txt"]


def test_sync_mode_same_seed_same_curves(tmp_path: Path) -> None:
    cfg = small_config()
    run(cfg, tmp_path / "a", progress=None)
    run(cfg, tmp_path / "b", progress=None)
    same = (tmp_path / "a/metrics.csv").read_bytes() == (tmp_path / "b/metrics.csv").read_bytes()
    assert same, diagnose(tmp_path / "a", tmp_path / "b")
    da = [r["digest_r1"] for r in rounds_csv(tmp_path / "a")]
    db = [r["digest_r1"] for r in rounds_csv(tmp_path / "b")]
    assert da == db and len(da) == 4


def test_visit_weighted_average(tmp_path: Path) -> None:
    res = run(small_config(iterations=100, method="visit_average"), tmp_path, progress=None)
    assert res.ok
    rows = rounds_csv(tmp_path)
    assert [r["method"] for r in rows] == ["visit_average", "visit_average"]
    assert all(r["all_equal"] == "true" for r in rows)


def test_itinerary_forward_then_backward_on_three_processes(tmp_path: Path) -> None:
    res = run(small_config(3, iterations=100), tmp_path, progress=None)
    assert res.ok
    rows = rounds_csv(tmp_path)
    assert len(rows) == 2
    shares = {}
    for robot in ("r1", "r2", "r3"):
        with open(tmp_path / f"shares_{robot}.csv", newline="") as fh:
            shares[robot] = [float(r["wall_time"]) for r in csv.DictReader(fh)]
        assert len(shares[robot]) == 2
    for k, row in enumerate(rows):
        assert row["visited"] == "r1 r2 r3" and int(row["hops"]) == 4  # 2 forward, 2 back
        assert row["all_equal"] == "true"
        # the aggregate is written into r3 first, then r2, then r1 on the way back
        assert shares["r3"][k] < shares["r2"][k] < shares["r1"][k]


def test_heterogeneous_one_agent_per_algorithm(tmp_path: Path) -> None:
    robots = (
        RobotSpec("r1", "r1", "qlearning"),
        RobotSpec("r2", "r4", "sarsa"),
        RobotSpec("r3", "r2", "qlearning"),
    )
    res = run(small_config(robots=robots, methods={"sarsa": "max"}), tmp_path, progress=None)
    assert res.ok
    assert res.agents_finished == {"fed_qlearning": 4, "fed_sarsa": 4}
    rows = rounds_csv(tmp_path)
    q = [r for r in rows if r["agent"] == "fed_qlearning"]
    s = [r for r in rows if r["agent"] == "fed_sarsa"]
    assert all(r["visited"] == "r1 r3" and r["method"] == "average" for r in q)
    assert all(r["visited"] == "r2" and r["method"] == "max" for r in s)
    assert all(r["all_equal"] == "true" for r in rows)
    assert all(r["digest_r2"] == "" for r in q)


def test_async_mode_with_real_time_factor(tmp_path: Path) -> None:
    # rtf 10: 100 iterations take at least 0.64 s of wall time; robots never wait
    cfg = small_config(mode="async", iterations=100, respite=25, rtf=10.0, rest_s=0.05)
    t0 = time.monotonic()
    res = run(cfg, tmp_path, progress=None)
    assert res.ok, (res.crashed, res.agents_finished)
    assert time.monotonic() - t0 >= 100 * 0.064 / 10
    rows = rounds_csv(tmp_path)
    assert len(rows) == 4
    assert all(r["all_equal"] == "true" for r in rows)
    curves = read_metrics(tmp_path / "metrics.csv")
    for rid, cur in curves.items():
        assert cur["iteration"].tolist() == list(range(1, 101))  # one row per iteration
        # async: writes land at whatever iteration the robot is at; each is counted in its row
        with open(tmp_path / f"shares_{rid}.csv", newline="") as fh:
            its = [int(w["iteration"]) for w in csv.DictReader(fh)]
        assert len(its) == 4 and min(its) >= 1
        marked = cur["shared"] > 0
        assert cur["iteration"][marked].tolist() == sorted(set(its))
        assert int(cur["shared"].sum()) == 4


def test_crashed_robot_is_reported_and_results_still_written(tmp_path: Path) -> None:
    import os
    import signal

    cfg = small_config(3, iterations=1500, respite=100, rtf=20.0, timeout_s=90, skip_after_s=1.5)
    t, box = run_in_thread(cfg, tmp_path)
    wait_rounds(tmp_path, "fed_qlearning", 2)
    nodes = json.loads((tmp_path / "nodes.json").read_text())
    pid = next(n["pid"] for n in nodes["nodes"] if n["robot"] == "r2")
    os.kill(pid, signal.SIGKILL)
    t.join(timeout=120)
    assert not t.is_alive()
    res: Results = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert not res.ok
    assert res.crashed == {"r2": -signal.SIGKILL}
    assert "CRASHED" in (tmp_path / "summary.md").read_text()
    rows = rounds_csv(tmp_path)
    assert rows[0]["visited"] == "r1 r2 r3"
    assert rows[-1]["visited"] == "r1 r3"  # the agent skips the dead stop
    assert "skip_after 1.5 s" in rows[-1]["skipped"]  # within the config's skip time
    assert rows[-1]["all_equal"] == "true"
    curves = read_metrics(tmp_path / "metrics.csv")
    assert len(set(curves["r1"]["iteration"].tolist())) == 1500
    assert 0 < len(curves["r2"]) < 1500
