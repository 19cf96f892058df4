"""``dfrl robot`` passes the bound flags (``--max-agents`` ...) to its embedded node."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from dfrl.experiments.processes import find_swipl

REPO = Path(__file__).resolve().parents[3]

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="swipl not installed")

#  A robot process built from a real command line; it reports its node's options and stops.
PROBE = """
import sys
from dfrl.experiments.cli import build_parser
from dfrl.experiments.cli.node import bounds_of_args
from dfrl.experiments.robot_host.service import RobotService
from dfrl.pybridge.terms import Atom, Var
args = build_parser().parse_args(sys.argv[1:])
svc = RobotService(args.host, args.port, ["1111"], None, args.workdir, bounds=bounds_of_args(args))
svc.start()
for name in ("max_agents", "agent_cpu_limit", "agent_memory_budget", "max_running_agents",
             "max_frame_size", "agent_wall_limit", "max_agents_per_peer"):
    sol = svc.bridge.call("node_option", svc.node_name, Atom(name), Var("V"), module="node")
    print("OPT", name, sol["V"], flush=True)
svc.close()
"""


def test_robot_passes_bounds_to_its_node(tmp_path: Path) -> None:
    run = subprocess.run(
        [
            sys.executable,
            "-c",
            PROBE,
            "robot",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--workdir",
            str(tmp_path),
            "--max-agents",
            "5",
            "--agent-cpu-limit",
            "infinite",
            "--agent-memory-budget",
            "268435456",
            "--max-running-agents",
            "3",
            "--agent-wall-limit",
            "90",
            "--max-agents-per-peer",
            "infinite",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    opts = dict(line.split()[1:3] for line in run.stdout.splitlines() if line.startswith("OPT "))
    assert opts == {
        "max_agents": "5",
        "agent_cpu_limit": "infinite",
        "agent_memory_budget": "268435456",
        "max_running_agents": "3",
        "max_frame_size": "33554432",
        "agent_wall_limit": "90.0",
        "max_agents_per_peer": "infinite",
    }, run.stdout + run.stderr


def test_robot_refuses_a_bad_bound(tmp_path: Path) -> None:
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "dfrl.experiments",
            "robot",
            "--port",
            "0",
            "--workdir",
            str(tmp_path),
            "--max-running-agents",
            "none",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=REPO,
    )
    assert run.returncode == 2 and "--max-running-agents" in run.stderr, run.stderr
