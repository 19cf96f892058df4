"""``dfrl join`` checked up front (issue 20): an arena that does not exist, a taken robot id or
an algorithm no agent learns with exit 2 with every problem named after its option, and
nothing is started; a joiner that passes the checks but fails to start (its robot host does
not answer) is a failed join: ``dfrl join`` exits 1, the run still completes (exit status 0)
and ``summary.md`` says the join failed. Real run, real ``dfrl join`` processes.
"""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from dfrl.experiments.driver.launcher import Results
from dfrl.experiments.processes import find_swipl

from .helpers import run_in_thread, small_config, stop_agents, wait_rounds

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def _join(out: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "dfrl", "join", str(out), *args],
        capture_output=True,
        text=True,
        timeout=120,
    )


def _dead_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_join_checked_and_failed_join_does_not_fail_the_run(tmp_path: Path) -> None:
    out = tmp_path / "run"
    # a long run (300 rounds, ~100 s), ended by a stop command once the joins were tried
    cfg = small_config(iterations=30000, respite=100, rtf=20.0, timeout_s=300)
    t, box = run_in_thread(cfg, out)
    wait_rounds(out, "fed_qlearning", 2)

    bad = _join(out, "--robot", "r9", "--arena", "r9")
    assert bad.returncode == 2, bad.stderr
    assert "nothing was started" in bad.stderr and "--arena:" in bad.stderr, bad.stderr
    assert "Traceback" not in bad.stderr, bad.stderr
    taken = _join(out, "--robot", "r1", "--arena", "r2", "--algo", "sarsa")
    assert taken.returncode == 2, taken.stderr
    assert "--robot: robot r1 is already part" in taken.stderr, taken.stderr
    assert "--algo: no agent of this experiment learns with sarsa" in taken.stderr, taken.stderr
    assert not (out / "logs" / "r9.err").exists()

    dead = _join(out, "--robot", "r4", "--arena", "r2", "--robot-host", f"127.0.0.1:{_dead_port()}")
    assert dead.returncode == 1, dead.stderr
    assert "Traceback" not in dead.stderr, dead.stderr

    stop_agents(out)
    t.join(timeout=180)
    res: Results = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    summary = (out / "summary.md").read_text()
    assert res.ok and res.complete, summary
    assert "join of r4 FAILED" in summary, summary
    assert "r4" not in res.crashed and "r4" not in res.iterations
