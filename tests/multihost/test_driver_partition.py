"""The driver's host is cut off the network mid-run (issue 33): the agent goes on among the
robot hosts, its lines wait in the robot nodes' outboxes, the driver says it is partitioned
instead of calling every robot LOST, and once the cut heals the run completes (exit 0) with
every round in ``rounds.csv``. Before, the agent waited for the console on every line and the
driver called all robots LOST and ended early."""

from __future__ import annotations

import csv
import json
import subprocess
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.agent_log import read_rounds_log

from dfrl.experiments.tools.netns import Lab, unavailable
from .test_federation_hosts import argv_of, start_readme_robots

WHY = unavailable()
TOKEN = 201734520938475610293847561029384756102
#: one run of about a minute with a 25 s cut: in the long tests, `scripts/test.sh -m slow`
pytestmark = [pytest.mark.skipif(WHY is not None, reason=WHY or ""), pytest.mark.slow]
HOSTS = ("h1", "h2", "h3")
AGENT = "fed_qlearning"
CUT_S = 25.0


def test_a_cut_driver_waits_and_the_run_completes(tmp_path: Path) -> None:
    with Lab([*HOSTS, "driver"]) as lab:
        start_readme_robots(lab, tmp_path, HOSTS, TOKEN)
        cfg = {
            "name": "cut",
            "iterations": 800,
            "respite": 100,
            "mode": "sync",
            "rtf": 4.0,
            "token": TOKEN,
            "timeout_s": 240,
            "partition_wait_s": 90,
            "robots": [
                {"id": f"r{i}", "arena": a, "robot_host": f"{lab[h].address}:7001"}
                for i, (h, a) in enumerate(zip(HOSTS, ("r1", "r4", "r2")), 1)
            ],
        }
        drv = tmp_path / "driver"
        drv.mkdir()
        (drv / "cut.json").write_text(json.dumps(cfg), encoding="utf-8")
        out = drv / "out"
        log = out / f"rounds_{AGENT}.log"
        driver = lab["driver"].popen(
            argv_of(f"dfrl run cut.json --out {out}"),
            cwd=drv,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        deadline = time.monotonic() + 90
        while (
            time.monotonic() < deadline
            and driver.poll() is None
            and len(read_rounds_log(log, AGENT).rounds) < 1
        ):
            time.sleep(0.1)
        # Execute: cut the driver's host off for CUT_S, then mend it
        lab.cut("driver")
        before = len(read_rounds_log(log, AGENT).rounds)
        time.sleep(CUT_S)
        kept = read_rounds_log(
            out / "none.log", AGENT, kept=sorted((tmp_path).glob(f"h*/**/rounds_{AGENT}.log"))
        )
        lab.mend("driver")
        _, stderr = driver.communicate(timeout=240)
    detail = f"exit {driver.returncode}\n{stderr[-4000:]}"
    # Assert: the agent went on during the cut (rounds kept on the robot hosts); the driver
    # said it was partitioned and healed, lost no robot, and completed every round
    assert len(kept.rounds) > before, (before, len(kept.rounds), detail)
    assert "DRIVER PARTITIONED" in stderr and "driver partition healed" in stderr, detail
    assert "LOST" not in stderr, detail
    assert driver.returncode == 0, detail
    with open(out / "rounds.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["round"]) for r in rows] == list(range(1, 9)), detail
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "federation complete" in summary and "driver partitioned from all 3" in summary, summary
