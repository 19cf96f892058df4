"""``dfrl collect`` after the driver of a run across hosts was killed (issue 20): the robot
hosts run the experiment to its end without their driver, and collecting from them gives the
rounds, metrics and summary an uninterrupted run with the same seed gives (up to wall-clock
columns). The control: the same run, not interrupted, on the same hosts.

The robot hosts' folders (``tmp/h<i>/dfrl-robot``) are not the driver's (``tmp/driver``): the
rounds logged after the kill, which the console (ended with its driver) never got, come from
the agent lines the robot nodes kept (``agent_logs/``, issue 33)."""

from __future__ import annotations

import csv
import io
import json
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.agent_log import kept_logs, read_rounds_log

from dfrl.experiments.tools.netns import Lab, unavailable
from .test_federation_hosts import argv_of, start_readme_robots

WHY = unavailable()
TOKEN = 318220964417253118400912235517760031279
#: about 80 s (two runs on three hosts): in the long tests, `scripts/test.sh -m slow`
pytestmark = [pytest.mark.skipif(WHY is not None, reason=WHY or ""), pytest.mark.slow]
AGENT = "fed_qlearning"
HOSTS = ("h1", "h2", "h3")
#: columns that hold wall-clock times (they differ between any two runs)
CLOCK_COLUMNS = {"start", "end", "duration_ms", "wall_s", "time_s"}


def _config(lab: Lab, name: str) -> dict:
    return {
        "name": name,
        "iterations": 500,
        "respite": 100,
        "mode": "sync",
        "rtf": 8.0,
        "seed": 7,
        "token": TOKEN,
        "timeout_s": 120,
        "robots": [
            {"id": f"r{i}", "arena": a, "robot_host": f"{lab[h].address}:7001"}
            for i, (h, a) in enumerate(zip(HOSTS, ("r1", "r4", "r2")), 1)
        ],
    }


def _csv_without_clock(path: Path) -> list[dict[str, str]]:
    rows = list(csv.DictReader(io.StringIO(path.read_text(encoding="utf-8"))))
    return [{k: v for k, v in r.items() if k not in CLOCK_COLUMNS} for r in rows]


def _summary_without_clock(path: Path) -> list[str]:
    """summary.md's lines without the collect section, with times and durations blanked (and
    the commit, which another checkout may have moved between the two runs)."""
    text = re.sub(
        r"## Collected after the driver stopped.*?\n\n(- .*\n)*\n?",
        "",
        path.read_text(encoding="utf-8"),
    )
    text = re.sub(r"\d+(\.\d+)?\s*(s|ms|min)\b", "T", text)
    text = re.sub(r"commit [0-9a-f]+", "commit C", text)
    return text.splitlines()


def test_collect_from_robot_hosts_equals_an_uninterrupted_run(tmp_path: Path) -> None:
    with Lab(["h1", "h2", "h3", "driver"]) as lab:
        start_readme_robots(lab, tmp_path, HOSTS, TOKEN)
        drv = tmp_path / "driver"
        drv.mkdir()
        # the control: an uninterrupted run
        (drv / "whole.json").write_text(json.dumps(_config(lab, "whole")), encoding="utf-8")
        whole = lab["driver"].run(
            argv_of("dfrl run whole.json --out whole"),
            cwd=drv,
            timeout=150,
            capture_output=True,
            text=True,
        )
        assert whole.returncode == 0, whole.stderr[-3000:]
        # the same run, its driver killed with SIGKILL once 2 rounds are logged
        (drv / "cut.json").write_text(json.dumps(_config(lab, "whole")), encoding="utf-8")
        out = drv / "cut"
        driver = lab["driver"].popen(
            argv_of(f"dfrl run cut.json --out {out}"),
            cwd=drv,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        deadline = time.monotonic() + 60
        while (
            time.monotonic() < deadline
            and driver.poll() is None
            and len(read_rounds_log(out / f"rounds_{AGENT}.log", AGENT).rounds) < 2
        ):
            time.sleep(0.05)
        assert driver.poll() is None, driver.communicate()[1][-3000:]
        driver.send_signal(signal.SIGKILL)
        driver.wait(timeout=10)
        assert not (out / "rounds.csv").exists()
        # collect waits for the robot hosts to end the run, then fetches their files
        collected = lab["driver"].run(
            argv_of(f"dfrl collect {out} --wait 90"),
            cwd=drv,
            timeout=150,
            capture_output=True,
            text=True,
        )
    detail = f"exit {collected.returncode}\n{collected.stderr[-3000:]}"
    assert collected.returncode == 0, detail
    # the console ended with its driver: the later rounds are only in the robot hosts' kept
    # logs (their folders are not the driver's; nothing writes the driver's path there)
    budget = len(read_rounds_log(drv / "whole" / f"rounds_{AGENT}.log", AGENT).rounds)
    console = read_rounds_log(out / f"rounds_{AGENT}.log", AGENT)
    assert len(console.rounds) < budget and console.finished is None, len(console.rounds)
    assert kept_logs(out, AGENT), sorted(p.name for p in out.iterdir())
    assert _csv_without_clock(out / "rounds.csv") == _csv_without_clock(
        drv / "whole" / "rounds.csv"
    )
    assert _csv_without_clock(out / "metrics.csv") == _csv_without_clock(
        drv / "whole" / "metrics.csv"
    )
    assert _summary_without_clock(out / "summary.md") == _summary_without_clock(
        drv / "whole" / "summary.md"
    )
    assert "federation complete" in (out / "summary.md").read_text(encoding="utf-8")
