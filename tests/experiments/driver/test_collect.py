"""``dfrl collect`` on real runs: after a driver killed with SIGKILL mid-run (its robot
processes left to end on their own), and on a run that ended normally (the control)."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.driver.collect import NotAResultsFolder, collect
from dfrl.experiments.driver.launcher import run
from dfrl.experiments.driver.results.agent_log import read_rounds_log
from dfrl.experiments.processes import find_swipl

from .launcher.helpers import small_config

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

AGENT = "fed_qlearning"


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "rounds.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _running(pid: int) -> bool:
    """``pid`` is a process that has not ended (a zombie nobody reaped has ended)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")


def _robot_pids(out: Path) -> list[int]:
    nodes = out / "nodes.json"
    if not nodes.is_file():
        return []
    return [int(n["pid"]) for n in json.loads(nodes.read_text())["nodes"] if n.get("pid")]


def test_collect_after_the_driver_was_killed(tmp_path: Path) -> None:
    # Prepare: a sync run of 2 robots that lasts ~10 s (rtf 10), driven by `dfrl run`
    cfg = {
        "name": "killed",
        "robots": [{"id": "r1", "arena": "r1"}, {"id": "r2", "arena": "r4"}],
        "iterations": 1000,
        "respite": 50,
        "mode": "sync",
        "rtf": 10.0,
        "seed": 1,
        "timeout_s": 120,
    }
    path = tmp_path / "killed.json"
    path.write_text(json.dumps(cfg))
    out = tmp_path / "out"
    log = out / f"rounds_{AGENT}.log"
    driver = subprocess.Popen(
        [sys.executable, "-m", "dfrl", "run", str(path), "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        # Execute: SIGKILL the driver alone (a crash: no handler runs, its children are left
        # in their own process groups) once 2 rounds are logged
        deadline = time.monotonic() + 90
        while (
            time.monotonic() < deadline
            and driver.poll() is None
            and len(read_rounds_log(log, AGENT).rounds) < 2
        ):
            time.sleep(0.05)
        assert driver.poll() is None, driver.communicate()[1][-3000:]
        driver.send_signal(signal.SIGKILL)
        driver.wait(timeout=10)
        before = read_rounds_log(log, AGENT).rounds
        pids = _robot_pids(out)
        assert len(before) >= 2 and len(pids) == 2
        # the robots read the end of their stdin as stop: they end on their own, soon
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and any(map(_running, pids)):
            time.sleep(0.2)
        assert not any(map(_running, pids)), "robot processes outlived their driver by 30 s"
        assert not (out / "rounds.csv").exists() and not (out / "summary.md").exists()
        collected = subprocess.run(
            [sys.executable, "-m", "dfrl", "collect", str(out), "--wait", "5"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        again = (out / "rounds.csv").read_bytes()
        second = subprocess.run(
            [sys.executable, "-m", "dfrl", "collect", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
        )
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait()
        for pid in _robot_pids(out):  # the robots the killed driver started, if left
            if _running(pid):
                os.kill(pid, signal.SIGKILL)
    # Assert: the end-of-run files are there, the rounds logged before the kill in them, and
    # the verdict is honest: the robots did not run their 1000 iterations
    assert collected.returncode == 1, collected.stderr
    assert "did NOT complete" in collected.stderr
    for name in ("rounds.csv", "metrics.csv", "summary.md", "tables/r1.npy", "tables/r2.npy"):
        assert (out / name).is_file(), name
    for rid in ("r1", "r2"):
        assert np.isfinite(np.load(out / "tables" / f"{rid}.npy")).all()
    rows = {int(r["round"]): r for r in _rows(out)}
    for rec in before:
        row = rows[rec.round]
        assert row["visited"] == " ".join(rec.visited) and row["method"] == rec.method
        if not rec.skipped:  # a round the agent finished before the kill: shared by both
            assert row["all_equal"] == "true" and row["digest_r1"] == row["digest_r2"]
    summary = (out / "summary.md").read_text()
    assert "federation INCOMPLETE" in summary and "federation complete" not in summary
    assert "MISSING rounds" in summary and "LOST robot r1: stopped at iteration" in summary
    assert "## Collected after the driver stopped (dfrl collect)" in summary
    # idempotent: collecting again writes the same rounds and the same verdict
    assert second.returncode == 1 and (out / "rounds.csv").read_bytes() == again


def test_collect_after_a_normal_end_writes_the_same_files(tmp_path: Path) -> None:
    # Prepare: a run that ended normally, and what it wrote
    res = run(small_config(2), tmp_path, progress=None)
    assert res.ok
    written = {n: (tmp_path / n).read_bytes() for n in ("rounds.csv", "metrics.csv")}
    # Execute
    again = collect(tmp_path, progress=None, wait_s=0)
    # Assert: the same rounds and metrics, the same verdict, and the summary says so
    assert {n: (tmp_path / n).read_bytes() for n in written} == written
    assert again.ok and again.complete and len(again.rounds) == 4
    assert not again.faults.lost and not again.faults.other
    summary = (tmp_path / "summary.md").read_text()
    assert "federation complete" in summary and "dfrl collect" in summary


def test_collect_refuses_a_folder_that_is_no_results_folder(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("keep me")
    with pytest.raises(NotAResultsFolder):
        collect(tmp_path, progress=None)
    assert main(["collect", str(tmp_path)]) == 2
    shutil.rmtree(tmp_path / "none", ignore_errors=True)
    assert main(["collect", str(tmp_path / "none")]) == 2
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]
