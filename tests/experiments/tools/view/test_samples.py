"""Robots' poses and curves reach the live view during a real run: a local robot through its
``DFRL_SAMPLE`` lines, a robot on a ``dfrl robot`` service through the fetch of its lines
file over the platform (the channel its status already travels)."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.launcher.experiment import run
from dfrl.experiments.tools.view import EVENTS_FILE, EventSource
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")
TOKEN = 1111


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_local_and_remote_robots_report_poses_and_progress(tmp_path: Path) -> None:
    port = _free_port()
    (tmp_path / "svc").mkdir()
    svc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dfrl.experiments",
            "robot",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--token",
            str(TOKEN),
            "--workdir",
            str(tmp_path / "svc"),
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = svc.stdout.readline()
        assert "listening on" in line, line + svc.stderr.read()
        cfg = ExperimentConfig(
            name="samples",
            iterations=600,
            respite=200,
            seed=1,
            mode="sync",
            rtf=6.0,
            token=TOKEN,
            timeout_s=120,
            robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4", robot_host=f"127.0.0.1:{port}")),
        )
        res = run(cfg, tmp_path / "out", progress=None)
        assert res.ok, res
    finally:
        svc.terminate()
        svc.communicate(timeout=30)
    lines = (tmp_path / "out" / EVENTS_FILE).read_text().splitlines()
    events = [json.loads(x) for x in lines]
    for rid in ("r1", "r2"):
        poses = [e for e in events if e["kind"] == "pose" and e["robot"] == rid]
        # 600 iterations at 6x real time: 6.4 s, a sample at most every 0.5 s, the last one
        assert len(poses) >= 3, (rid, poses)
        its = [p["iteration"] for p in poses]
        assert its == sorted(its) and its[-1] == 600, its
        assert all(-1.0 < p["x"] < 1.0 and -1.0 < p["y"] < 1.0 for p in poses)
        assert len({(p["x"], p["y"]) for p in poses}) >= 2  # it drove
    progress = [e for e in events if e["kind"] == "progress"]
    assert {e["robot"] for e in progress} == {"r2"}  # the remote one only
    assert progress[-1]["iteration"] == 600 and progress[-1]["q_sum"] != 0.0
    assert not [e for e in events if e["kind"] == "error"], events
    # the agent is seen at the remote robot too (its DFRL_EVENT lines come with its samples):
    # the status line and the view say where the agent is, not "at -"
    for rid in ("r1", "r2"):
        hops = [e for e in events if e["kind"] == "hop" and e["robot"] == rid]
        assert {h["phase"] for h in hops} == {"forward", "backward"}, (rid, hops)
    # the view serves them: poses of both, the remote robot's curve before its files came
    src = EventSource(tmp_path / "out")
    got = src.drain()
    assert {e["robot"] for e in got if e["kind"] == "pose"} == {"r1", "r2"}
    assert any(e["kind"] == "progress" and e["robot"] == "r2" for e in got)
