"""A robot host killed -9 mid-run and restarted with the same command and workdir, as the
docs advise (issue 20): the driver sees the service back with no experiment, configures it
again from its checkpoint and starts it; the agent visits its stop again; the summary says
which rounds it missed, when it was lost and that it rejoined from its checkpoint, and the
run is not called complete. The control is the run's own first rounds (all three visited)."""

from __future__ import annotations

import csv
import json
import signal
import subprocess
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.agent_log import read_rounds_log
from dfrl.experiments.tokens import write_secret_file

from dfrl.experiments.tools.netns import Lab, unavailable
from .test_federation_hosts import README, argv_of, section_blocks, wait_line

WHY = unavailable()
TOKEN = 227561390128845561202938475610293847561
#: 50-100 s: in the long tests (`scripts/test.sh -m slow`)
pytestmark = [pytest.mark.skipif(WHY is not None, reason=WHY or ""), pytest.mark.slow]
AGENT = "fed_qlearning"


def test_a_restarted_robot_host_rejoins_from_its_checkpoint(tmp_path: Path) -> None:
    robot_cmd = section_blocks(README.read_text(encoding="utf-8"))["robot"][1].strip()
    with Lab(["h1", "h2", "h3", "driver"]) as lab:
        procs = {}

        def start(h: str) -> subprocess.Popen:
            p = lab[h].popen(
                argv_of(robot_cmd.replace("HOSTn", lab[h].address)),
                cwd=tmp_path / h,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
            )
            wait_line(p, "dfrl robot listening on", 60)
            return p

        for h in ("h1", "h2", "h3"):
            (tmp_path / h).mkdir()
            write_secret_file(tmp_path / h / "dfrl.token", [TOKEN])
            procs[h] = start(h)
        cfg = {
            "name": "restart",
            "iterations": 1200,
            "respite": 100,
            "mode": "sync",
            "rtf": 4.0,
            "seed": 3,
            "token": TOKEN,
            "timeout_s": 150,
            "robots": [
                {"id": f"r{i}", "arena": a, "robot_host": f"{lab[h].address}:7001"}
                for i, (h, a) in enumerate(zip(("h1", "h2", "h3"), ("r1", "r4", "r2")), 1)
            ],
        }
        drv = tmp_path / "driver"
        drv.mkdir()
        (drv / "restart.json").write_text(json.dumps(cfg), encoding="utf-8")
        out = drv / "out"
        driver = lab["driver"].popen(
            argv_of(f"dfrl run restart.json --out {out}"),
            cwd=drv,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        log = out / f"rounds_{AGENT}.log"
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(read_rounds_log(log, AGENT).rounds) < 3:
            time.sleep(0.1)
        procs["h3"].send_signal(signal.SIGKILL)
        procs["h3"].wait(timeout=10)
        time.sleep(2.0)
        procs["h3"] = start("h3")  # the same command in the same folder
        stdout, stderr = driver.communicate(timeout=200)
    detail = f"exit {driver.returncode}\n{stderr[-3000:]}"
    with open(out / "rounds.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["round"]) for r in rows] == list(range(1, 13)), detail
    assert all("r3" in r["visited"].split() for r in rows[:3]), rows[:3]
    missed = [int(r["round"]) for r in rows if "r3" not in r["visited"].split()]
    assert missed, detail
    back = [
        int(r["round"])
        for r in rows
        if int(r["round"]) > missed[0] and "r3" in r["visited"].split()
    ]
    assert back, f"r3 was never visited again after round {missed[0]}\n{detail}"
    for r in rows:
        if int(r["round"]) >= back[0]:
            assert r["all_equal"] == "true" and r["visited"].split() == ["r1", "r2", "r3"], r
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert f"rejoined at round {back[0]} from its checkpoint at iteration" in summary, summary
    assert "federation INCOMPLETE" in summary and "federation complete" not in summary, summary
    assert driver.returncode == 1, detail
    assert "resumed from its checkpoint at iteration" in stderr, detail
    assert (out / "metrics_r3.csv").is_file()
