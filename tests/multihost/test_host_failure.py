"""A robot host dies mid-run (kill -9 of its ``dfrl robot``): the agent goes on without it and
the driver reports it -- ``skipped`` in rounds.csv, LOST in summary.md, exit status 1."""

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
TOKEN = 463709187335281729054263357812893156702
pytestmark = pytest.mark.skipif(WHY is not None, reason=WHY or "")


def test_a_killed_robot_host_is_skipped_and_reported(tmp_path: Path) -> None:
    robot_cmd = section_blocks(README.read_text(encoding="utf-8"))["robot"][1].strip()
    with Lab(["h1", "h2", "h3", "driver"]) as lab:
        procs = {}
        for h in ("h1", "h2", "h3"):
            (tmp_path / h).mkdir()
            write_secret_file(tmp_path / h / "dfrl.token", [TOKEN])  # the README's token file
            procs[h] = lab[h].popen(
                argv_of(robot_cmd.replace("HOSTn", lab[h].address)),
                cwd=tmp_path / h,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
            )
            wait_line(procs[h], "dfrl robot listening on", 60)
        cfg = {
            "name": "fail",
            "iterations": 600,
            "respite": 100,
            "mode": "sync",
            "rtf": 4.0,
            "token": TOKEN,
            "timeout_s": 120,
            "robots": [
                {"id": f"r{i}", "arena": a, "robot_host": f"{lab[h].address}:7001"}
                for i, (h, a) in enumerate(zip(("h1", "h2", "h3"), ("r1", "r4", "r2")), 1)
            ],
        }
        drv = tmp_path / "driver"
        drv.mkdir()
        (drv / "fail.json").write_text(json.dumps(cfg), encoding="utf-8")
        out = drv / "out"
        driver = lab["driver"].popen(
            argv_of(f"dfrl run fail.json --out {out}"),
            cwd=drv,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        deadline = time.monotonic() + 60
        while (
            time.monotonic() < deadline
            and len(read_rounds_log(out / "rounds_fed_qlearning.log", "fed_qlearning").rounds) < 1
        ):
            time.sleep(0.1)
        procs["h3"].send_signal(signal.SIGKILL)
        stdout, stderr = driver.communicate(timeout=150)
        detail = f"exit {driver.returncode}\n{stderr[-3000:]}"
        assert driver.returncode == 1, detail
        with open(out / "rounds.csv", newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
        assert [int(r["round"]) for r in rows] == list(range(1, 7)), detail
        late = [r for r in rows if "r3" not in r["visited"].split()]
        assert late, detail
        for r in late:
            assert r["skipped"].startswith("r3: "), r
            assert r["all_equal"] == "true", r
        summary = (out / "summary.md").read_text(encoding="utf-8")
        assert "federation INCOMPLETE" in summary and "LOST robot r3" in summary, summary
        assert "skipped stops" in summary, summary
        assert (out / "metrics_r1.csv").is_file() and (out / "metrics_r2.csv").is_file()
