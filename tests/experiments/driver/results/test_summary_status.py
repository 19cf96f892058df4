"""``summary.md`` opens with the truth: the run's status (complete / INCOMPLETE / NEVER
STARTED, and why), its itinerary, what its agents carried and the learners' settings. Real
runs on real robot processes: a robot host that refuses the run's token, a robot killed
mid-run, a complete run of Q-learning and FedAvg'd linear robots, a grid federation (its
distillation residuals in the summary and in ``distillation.csv``); and the FedAvg weights'
matching of reads to rounds on hand-made records."""
from __future__ import annotations

import csv
import json
import os
import signal
from pathlib import Path

import pytest

from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.driver.launcher import Results, run
from dfrl.experiments.driver.results.carried import fedavg_weights
from dfrl.experiments.driver.results.rounds import Share
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.processes import find_swipl

from ..launcher.helpers import (diagnose, robot_service, run_in_thread, small_config,
                                wait_rounds)

needs_swipl = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def _head(out: Path, n: int = 4) -> list[str]:
    """The summary's first ``n`` lines after its title and config line."""
    return (out / "summary.md").read_text(encoding="utf-8").splitlines()[4:4 + n]


def _csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))



@needs_swipl
def test_a_run_refused_by_a_robot_host_never_started(tmp_path: Path) -> None:
    svc, port = robot_service(tmp_path / "svc", token=1111)
    try:
        cfg = small_config(2, iterations=200, respite=100, token=2222)    # not the host's
        cfg = cfg.replace(robots=(cfg.robots[0],
                                  RobotSpec("r2", "r4", robot_host=f"127.0.0.1:{port}")))
        with pytest.raises(ExperimentError, match="tokens"):
            run(cfg, tmp_path / "out", progress=None)
    finally:
        svc.terminate()
        svc.communicate(timeout=30)
    out = tmp_path / "out"
    head = _head(out, 3)
    assert head[0] == "**Status: NEVER STARTED**", head
    assert head[2].startswith(f"- no agent was launched and no round ran: starting robot r2 on "
                              f"its robot host 127.0.0.1:{port} failed: robot r2: its robot "
                              f"host 127.0.0.1:{port} accepts none of this run's tokens"), head
    assert "--token-file" in head[2], head
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "federation complete" not in summary and "## Faults: federation INCOMPLETE" in summary
    assert "- MISSING rounds of fed_qlearning (2): 1, 2" in summary
    assert "(planned; never launched)" in summary
    assert "nan ms" not in summary and "- median round time: no round completed" in summary


@needs_swipl
def test_a_robot_killed_mid_run_makes_it_incomplete_with_its_missed_rounds(
        tmp_path: Path) -> None:
    cfg = small_config(3, iterations=1500, respite=100, rtf=20.0, timeout_s=90,
                       skip_after_s=1.5)
    t, box = run_in_thread(cfg, tmp_path)
    wait_rounds(tmp_path, "fed_qlearning", 2)
    nodes = json.loads((tmp_path / "nodes.json").read_text())
    os.kill(next(n["pid"] for n in nodes["nodes"] if n["robot"] == "r2"), signal.SIGKILL)
    t.join(timeout=120)
    assert not t.is_alive()
    res: Results = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert not res.ok
    missed = sorted(int(r["round"]) for r in _csv(tmp_path / "rounds.csv")
                    if "r2" not in r["visited"].split())
    assert missed and missed[-1] == 15, diagnose(tmp_path)
    head = _head(tmp_path, 8)
    assert head[:3] == ["**Status: INCOMPLETE**", "",
                        "- fed_qlearning: 15 of 15 planned rounds done"], head
    shown = ", ".join(map(str, missed[:20]))
    assert any(line.startswith(f"- r2 missed {len(missed)} round(s) of fed_qlearning: {shown}")
               for line in head), head
    assert any(line.startswith("- LOST r2:") or line.startswith("- r2 crashed")
               for line in head), head
    assert "federation complete" not in (tmp_path / "summary.md").read_text()


@needs_swipl
def test_a_complete_run_says_what_ran(tmp_path: Path) -> None:
    robots = (RobotSpec("r1", "r1", "qlearning"), RobotSpec("r2", "r4", "linear"),
              RobotSpec("r3", "r2", "linear"))
    cfg = small_config(robots=robots, iterations=200, respite=100,
                       trainer={"learner": {"gamma": 0.9}})
    res = run(cfg, tmp_path, progress=None)
    assert res.ok, diagnose(tmp_path)
    lines = (tmp_path / "summary.md").read_text(encoding="utf-8").splitlines()
    assert lines[4:7] == ["**Status: complete**", "",
                          "- every planned round ran, every robot took part in every round of "
                          "its agent (fed_qlearning: 2 of 2 planned rounds, fed_linear: 2 of 2 "
                          "planned rounds)"]
    assert ("- itinerary of fed_linear: chain r2 -> r3 and back (reads on the way out, writes "
            "on the way back), 2 rounds planned") in lines
    assert ("- fed_qlearning carried Q-tables (qlearning), aggregated by average (the "
            "element-wise mean of the robots' tables)") in lines
    # FedAvg: every robot's samples when read, per round, in fedavg_weights.csv and the summary
    weights = _csv(tmp_path / "fedavg_weights.csv")
    assert [(w["round"], w["robot"], w["samples"]) for w in weights] == [
        ("1", "r2", "100"), ("1", "r3", "100"), ("2", "r2", "200"), ("2", "r3", "200")]
    assert all(w["agent"] == "fed_linear" and float(w["weight"]) == 0.5 for w in weights)
    assert any(line.startswith("- fed_linear carried parameter vectors (linear), averaged by "
                               "FedAvg") and "weights in round 2: r2 200 samples (0.500), r3 "
               "200 samples (0.500)" in line for line in lines), lines
    # the learners' settings from the config: gamma 0.9 given, the rest the defaults
    assert ("- r1 (qlearning): alpha 0.2, initial Q 0, gamma 0.9, epsilon linear 0.3 -> 0.02 "
            "over 4,000 updates") in lines
    assert any(line.startswith("- r2, r3 (linear): tile coding 4 tilings x 8 tiles, alpha "
                               "0.05, gamma 0.9") for line in lines), lines
    assert not (tmp_path / "distillation.csv").exists()


@needs_swipl
def test_a_grid_run_reports_its_distillation_residuals(tmp_path: Path) -> None:
    robots = (RobotSpec("r1", "r1", "qlearning"), RobotSpec("r2", "r4", "linear"))
    cfg = small_config(robots=robots, iterations=200, respite=100, federation="grid")
    res = run(cfg, tmp_path, progress=None)
    assert res.ok, diagnose(tmp_path)
    rows = _csv(tmp_path / "distillation.csv")
    # one row per write to the function learner, none for the tabular robot
    assert [(r["robot"], r["agent"], r["round"]) for r in rows] == [
        ("r2", "fed_grid", "1"), ("r2", "fed_grid", "2")]
    for r in rows:
        assert 0 <= float(r["rms_after"]) <= float(r["rms_before"]) and int(r["steps"]) > 0
    summary = (tmp_path / "summary.md").read_text(encoding="utf-8")
    assert summary.splitlines()[4] == "**Status: complete**"
    assert "fed_grid carried Q-tables on the discretised state grid" in summary
    assert "r2 (function learners) take part through grid views" in summary
    for r in rows:
        cell = f"{float(r['rms_before']):.4f} -> {float(r['rms_after']):.4f}"
        assert f"| fed_grid | {r['round']} | {cell} |" in summary
    assert "count as unequal" in summary


def test_fedavg_weights_match_each_write_to_the_last_read_before_it(tmp_path: Path) -> None:
    # r1 read at t=1 (50 samples) and t=3 (150); r2 at t=1.5 (40) and t=3.5 (90); writes of
    # round 1 at t=2 (both), of round 2 at t=4 (r1) and t=4.5 (r2); r3 recorded no read
    for rid, reads in (("r1", [(1.0, 50), (3.0, 150)]), ("r2", [(1.5, 40), (3.5, 90)])):
        with open(tmp_path / f"weights_{rid}.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(("robot", "iteration", "wall_time", "samples"))
            w.writerows((rid, s, t, s) for t, s in reads)
    shares = {"r1": [Share("r1", 1, 50, 2.0, "a", 1, "fed_linear"),
                     Share("r1", 2, 150, 4.0, "b", 2, "fed_linear")],
              "r2": [Share("r2", 1, 40, 2.0, "a", 1, "fed_linear"),
                     Share("r2", 2, 90, 4.5, "b", 2, "fed_linear")],
              "r3": [Share("r3", 1, 40, 2.0, "c", 1, "fed_qlearning")]}
    got = [(w.round, w.robot, w.samples, w.weight) for w in fedavg_weights(tmp_path, shares)]
    assert got == [(1, "r1", 50, 50 / 90), (1, "r2", 40, 40 / 90),
                   (2, "r1", 150, 150 / 240), (2, "r2", 90, 90 / 240)]
    (tmp_path / "weights_r2.csv").write_text("robot,iteration,wall_time,samples\nr2,1,x,4\n")
    with pytest.raises(ValueError, match=r"weights_r2.csv:2: not a weights row"):
        fedavg_weights(tmp_path, shares)
