"""A federation survives the death of the robot process the agent is running on (issue 8).

Three robot node processes, sync mode. After round 1 the agent is switched to an aggregation
method that takes half a second per robot (``slow_method.pl``), so that it stays on each stop
for a while after reading its table; when it has read robot r2's table, r2's process is killed
with SIGKILL while the agent is there. The stop the agent came from (r1) holds its checkpoint
under a lease; when the lease expires and neither r2 nor any other stop knows of the agent, r1
resurrects it with a higher epoch, and the federation completes its planned rounds on r1 and r3.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.launcher import inject_method
from dfrl.experiments.driver.results.agent_log import read_rounds_log

from .helpers import launcher_in_thread, wait_rounds
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

SLOW = Path(__file__).parent / "slow_method.pl"


def test_run_completes_when_the_agents_host_is_killed(tmp_path: Path) -> None:
    # Prepare: 6 rounds of 200 iterations at rtf 8 (1.6 s of robot time each).
    cfg = ExperimentConfig(
        name="kill",
        robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4"), RobotSpec("r3", "r2")),
        iterations=1200,
        respite=200,
        seed=3,
        mode="sync",
        rtf=8.0,
        timeout_s=120,
        tolerate_lost_robots=1,
    )
    launcher, runner, box = launcher_in_thread(cfg, tmp_path)
    wait_rounds(tmp_path, "fed_qlearning", 1)
    assert inject_method(tmp_path, SLOW, "slow") == {"fed_qlearning": "applied"}
    # Execute: the first time the agent reads r2's table with the slow method (it then stays
    # there for 0.5 s), kill r2's process.
    killed = None
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and runner.is_alive() and killed is None:
        at = launcher.agent_at("fed_qlearning")
        if at is not None and at[0] == "r2" and at[1] == "get" and at[2] >= 400:
            killed = launcher.robots()["r2"].status().pid
            assert killed is not None
            os.kill(killed, signal.SIGKILL)
        time.sleep(0.005)
    assert killed is not None, "the agent never read r2's table in round 2 or later"
    runner.join(timeout=200)
    # Assert: every planned round logged once, r2 skipped after the kill, a resurrection,
    # r1 and r3 holding the same table after each later share.
    assert not runner.is_alive()
    res = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    log = read_rounds_log(tmp_path / "rounds_fed_qlearning.log", "fed_qlearning")
    assert [r.round for r in log.rounds] == list(range(1, cfg.rounds + 1)), log
    assert log.finished == cfg.rounds
    assert len(log.resurrections) >= 1, log
    assert any("r2" in (s.robot for s in r.skipped) for r in log.rounds)
    assert all(list(r.visited) == ["r1", "r3"] for r in log.rounds[-2:]), log.rounds[-2:]
    assert res.ok, (res.crashed, res.agents_finished)
    assert "r2" in res.crashed or "r2" in (res.faults.lost if res.faults else {})
    summary = (tmp_path / "summary.md").read_text()
    assert "## Faults: federation complete" in summary, summary
    assert "resurrected at" in summary and "LOST robot r2" in summary, summary
