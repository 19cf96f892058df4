"""Robots joining a running experiment (the config's ``joins``)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from dfrl.experiments.config import JoinSpec, RobotSpec
from dfrl.experiments.launcher import run
from dfrl.experiments.results.metrics import read_metrics

from .helpers import rounds_csv, small_config

pytestmark = pytest.mark.skipif(shutil.which("swipl") is None, reason="needs swipl")


def test_robot_joins_running_experiment(tmp_path: Path) -> None:
    cfg = small_config(iterations=1000, respite=100, rtf=20.0,
                  joins=(JoinSpec(RobotSpec("r3", "r5"), after_round=2),))
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
    assert "r3" in curves and 0 < len(curves["r3"]) <= 800
    nodes = json.loads((tmp_path / "nodes.json").read_text())
    assert [n["robot"] for n in nodes["nodes"]] == ["r1", "r2", "r3"]


