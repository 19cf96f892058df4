"""A run whose token a robot host does not accept names the robot, the robot host and both
ways out, ``--token-file`` among them (issue 36: it said "robot failed: No permission to
access platform ... (the platform accepts none of the tokens)"). A real ``dfrl robot``
started with one token, a real ``dfrl run`` with another; the control is the same run with
the host's token, which completes."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from dfrl.experiments.processes import find_swipl
from dfrl.experiments.tokens import env_with_tokens

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="swipl not installed")

HOST_TOKEN = "h" * 40
OTHER_TOKEN = "o" * 40


@pytest.fixture
def robot_host(tmp_path: Path) -> Iterator[int]:
    """A ``dfrl robot`` on 127.0.0.1 with HOST_TOKEN; its port."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    svc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dfrl",
            "robot",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--workdir",
            str(tmp_path / "svc"),
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env_with_tokens([HOST_TOKEN]),
    )
    try:
        assert svc.stdout is not None
        line = svc.stdout.readline()
        assert "listening on" in line, line
        yield port
    finally:
        svc.terminate()
        svc.communicate(timeout=30)


def _run(tmp_path: Path, port: int, token: str, out: str) -> subprocess.CompletedProcess[str]:
    cfg = tmp_path / "cfg.json"
    cfg.write_text(
        json.dumps(
            {
                "name": "tok",
                "iterations": 40,
                "respite": 20,
                "robots": [{"id": "r1", "arena": "r1", "robot_host": f"127.0.0.1:{port}"}],
            }
        )
    )
    token_file = tmp_path / f"{out}.token"
    token_file.write_text(token + "\n")
    token_file.chmod(0o600)
    env = {k: v for k, v in os.environ.items() if k != "DFRL_TOKEN"}
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "dfrl",
            "run",
            str(cfg),
            "--out",
            str(tmp_path / out),
            "--token-file",
            str(token_file),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        env=env,
    )


def test_a_token_the_robot_host_refuses_names_robot_host_and_fix(
    robot_host: int, tmp_path: Path
) -> None:
    done = _run(tmp_path, robot_host, OTHER_TOKEN, "wrong")
    assert done.returncode == 1, done.stderr
    assert (
        f"robot r1: its robot host 127.0.0.1:{robot_host} accepts none of this run's tokens"
    ) in done.stderr, done.stderr
    assert "--token-file FILE" in done.stderr and "restart that dfrl robot" in done.stderr
    assert OTHER_TOKEN not in done.stderr and HOST_TOKEN not in done.stderr


def test_the_control_the_host_token_runs(robot_host: int, tmp_path: Path) -> None:
    done = _run(tmp_path, robot_host, HOST_TOKEN, "right")
    assert done.returncode == 0, done.stderr
    assert "accepts none" not in done.stderr
