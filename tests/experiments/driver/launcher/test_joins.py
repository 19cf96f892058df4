"""Robots joining a running experiment: the config's ``joins`` and ``dfrl join``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dfrl.experiments.driver.config import JoinSpec, RobotSpec
from dfrl.experiments.config_rules import ConfigError
from dfrl.experiments.driver.launcher import join_robot, run
from dfrl.experiments.driver.results.metrics import read_metrics

from .helpers import rounds_csv, run_in_thread, small_config, wait_rounds
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def test_robot_joins_running_experiment(tmp_path: Path) -> None:
    cfg = small_config(
        iterations=1000,
        respite=100,
        rtf=20.0,
        joins=(JoinSpec(RobotSpec("r3", "r5"), after_round=2),),
    )
    res = run(cfg, tmp_path, progress=None)
    assert res.ok, (res.crashed, res.agents_finished)
    rows = rounds_csv(tmp_path)
    visited = [r["visited"] for r in rows]
    assert visited[:2] == ["r1 r2", "r1 r2"]
    first = visited.index("r1 r2 r3")
    assert all(v == "r1 r2 r3" for v in visited[first:])
    assert 2 <= first < len(rows)
    assert all(r["all_equal"] == "true" for r in rows)
    curves = read_metrics(tmp_path / "metrics.csv")
    assert "r3" in curves and 0 < len(set(curves["r3"]["iteration"].tolist())) <= 800
    nodes = json.loads((tmp_path / "nodes.json").read_text())
    assert [n["robot"] for n in nodes["nodes"]] == ["r1", "r2", "r3"]


def test_dfrl_join_asks_the_launcher_through_the_platform(tmp_path: Path) -> None:
    # Prepare: a running experiment (rtf 20: 100 iterations take 0.32 s)
    cfg = small_config(iterations=2000, respite=100, rtf=20.0)
    t, box = run_in_thread(cfg, tmp_path)
    wait_rounds(tmp_path, "fed_qlearning", 2)
    # Execute: another process's view (join_robot opens its own console node and posts the
    # request to the launcher's; no request files)
    entry = join_robot(tmp_path, "r3", "r5", iterations=600)
    with pytest.raises(ConfigError, match="already part"):  # checked up front: exit 2
        join_robot(tmp_path, "r3", "r5")
    t.join(timeout=120)
    # Assert
    assert not t.is_alive()
    res = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert res.ok
    assert entry["robot"] == "r3" and entry["joined"] is True and entry["port"] > 0
    assert not (tmp_path / "join_requests").exists()
    visited = [r["visited"] for r in rounds_csv(tmp_path)]
    assert "r1 r2 r3" in visited and visited[0] == "r1 r2"
    nodes = json.loads((tmp_path / "nodes.json").read_text())
    assert [n["robot"] for n in nodes["nodes"]] == ["r1", "r2", "r3"]
    assert len(nodes["console"]) == 2


def test_a_robot_that_joins_after_an_injection_gets_the_injected_method(tmp_path: Path) -> None:
    # Prepare: a running experiment whose agent switched to an injected method
    from dfrl.experiments.driver.launcher import inject_method
    from dfrl.platform_pl import DFRL_AGENT_DIR

    median = DFRL_AGENT_DIR / "examples" / "median_method.pl"
    cfg = small_config(iterations=2000, respite=100, rtf=20.0)
    t, box = run_in_thread(cfg, tmp_path)
    wait_rounds(tmp_path, "fed_qlearning", 2)
    assert inject_method(tmp_path, median, "median") == {"fed_qlearning": "applied"}
    # Execute: a robot joins afterwards (its node never had the program loaded by inject)
    join_robot(tmp_path, "r3", "r5", iterations=600)
    t.join(timeout=120)
    # Assert: the driver kept the program and loaded it into r3, so rounds with r3 use median
    assert not t.is_alive()
    res = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert res.ok
    assert (tmp_path / "programs" / "median_method.pl").read_text() == median.read_text()
    rows = rounds_csv(tmp_path)
    with_r3 = [r for r in rows if r["visited"] == "r1 r2 r3"]
    assert with_r3 and all(r["method"] == "median" for r in with_r3)
    assert all(r["all_equal"] == "true" and not r.get("error") for r in with_r3), with_r3
