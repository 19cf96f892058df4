"""A federation survives the death of the robot process the agent is running on (issue 8).

Three robot node processes, sync mode; when the agent is reading robot r2's table (the
forward pass is on r2's node), r2's process is killed with SIGKILL. The stop the agent came
from holds its checkpoint under a lease; when the lease expires it resurrects the agent with a
higher epoch, and the federation completes its planned rounds on r1 and r3.

KNOWN GAP (issue 8, open): with real robot node processes no resurrection happens (seen twice:
r1 and r3 wait at their boundary until the experiment's timeout), while the same mechanism
passes with plain swipl nodes (tests/platform/test_dfrl_faults.py). Marked slow and xfail until
fixed; run it with `scripts/test.sh -m slow -k agents_host`.
"""
from __future__ import annotations

import os
import shutil
import signal
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from dfrl.experiments.config import ExperimentConfig, RobotSpec
from dfrl.experiments.launcher import Launcher
from dfrl.experiments.results.agent_log import read_rounds_log

pytestmark = pytest.mark.skipif(shutil.which("swipl") is None, reason="needs swipl")


@pytest.mark.slow
@pytest.mark.xfail(reason="no resurrection on pybridge robot nodes yet (issue 8)", strict=False)
def test_run_completes_when_the_agents_host_is_killed(tmp_path: Path) -> None:
    # Prepare: 6 rounds; rtf 8 makes a respite of 200 iterations last 1.6 s, so the kill lands
    # in the middle of a run, not after it.
    cfg = ExperimentConfig(name="kill", robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4"),
                                                RobotSpec("r3", "r2")),
                           iterations=1200, respite=200, seed=3, mode="sync", rtf=8.0,
                           timeout_s=90, tolerate_lost_robots=1)
    launcher = Launcher(cfg, tmp_path, progress=None)
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            box["res"] = launcher.run()
        except BaseException as exc:  # noqa: BLE001 - reported by the assertion below
            box["exc"] = exc

    runner = threading.Thread(target=target)
    runner.start()
    # Execute: wait (bounded) for round 2 to start on r2's node, then kill r2's process.
    st = launcher.state
    killed = None
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and runner.is_alive():
        at = st.agent_at.get("fed_qlearning")
        if at is not None and at[0] == "r2" and at[1] == "get" and at[2] >= 400:
            killed = st.children["r2"].proc.pid
            os.kill(killed, signal.SIGKILL)
            break
        time.sleep(0.002)
    assert killed is not None, "the agent never read r2's table in round 2 or later"
    runner.join(timeout=200)
    # Assert: every planned round logged once, r2 skipped after the kill, a resurrection,
    # r1 and r3 still holding the same table after each share.
    assert not runner.is_alive()
    res = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    log = read_rounds_log(tmp_path / "rounds_fed_qlearning.log", "fed_qlearning")
    assert [r.round for r in log.rounds] == list(range(1, cfg.rounds + 1)), log
    assert log.finished == cfg.rounds
    assert len(log.resurrections) >= 1, log
    assert any("r2" in (s.robot for s in r.skipped) for r in log.rounds)
    assert all(r.visited[0] == "r1" and r.visited[-1] == "r3" for r in log.rounds[-2:])
    assert res.ok, (res.crashed, res.agents_finished)
    assert "r2" in res.crashed or "r2" in (res.faults.lost if res.faults else {})
