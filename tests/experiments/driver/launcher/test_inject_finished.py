"""``dfrl inject`` (and ``dfrl join``) into a run that finished says so, with the run's name and
when it ended, instead of "cannot connect" (issue 36). A real two-robot run, then the real
commands; the control: the same folder without its ``summary.md`` (a run whose driver
vanished) is not called finished."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="swipl not installed")


def _dfrl(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "dfrl", *args], capture_output=True, text=True, timeout=300, cwd=cwd
    )


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The results folder of a real run that ended."""
    tmp = tmp_path_factory.mktemp("finished")
    cfg = tmp / "cfg.json"
    cfg.write_text(
        json.dumps(
            {
                "name": "over",
                "iterations": 40,
                "respite": 20,
                "robots": [{"id": "r1", "arena": "r1"}, {"id": "r2", "arena": "r2"}],
            }
        )
    )
    done = _dfrl(tmp, "run", str(cfg), "--out", str(tmp / "out"))
    assert done.returncode == 0, done.stderr
    return tmp / "out"


def test_inject_into_a_finished_run_says_it_finished(finished: Path, tmp_path: Path) -> None:
    program = tmp_path / "mine.pl"
    program.write_text("dfrl_aggregation:aggregate_init(mine, qtable(_, V), V).\n")
    done = _dfrl(tmp_path, "inject", str(finished), "--program", str(program), "--method", "mine")
    assert done.returncode == 1, done.stderr
    assert re.search(
        rf"run over \({re.escape(str(finished))}\) finished at "
        r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC \(its summary.md\); nothing to "
        r"inject into",
        done.stderr,
    ), done.stderr
    assert "cannot connect" not in done.stderr and "mine.pl refused" not in done.stderr


def test_join_into_a_finished_run_says_it_finished(finished: Path, tmp_path: Path) -> None:
    done = _dfrl(tmp_path, "join", str(finished), "--robot", "r6", "--arena", "r2")
    assert done.returncode == 1, done.stderr
    assert "run over" in done.stderr and "nothing to join" in done.stderr, done.stderr


def test_the_control_without_summary_it_is_not_called_finished(
    finished: Path, tmp_path: Path
) -> None:
    vanished = tmp_path / "vanished"
    shutil.copytree(finished, vanished)
    (vanished / "summary.md").unlink()
    program = tmp_path / "mine.pl"
    program.write_text("dfrl_aggregation:aggregate_init(mine, qtable(_, V), V).\n")
    done = _dfrl(
        tmp_path,
        "inject",
        str(vanished),
        "--program",
        str(program),
        "--method",
        "mine",
        "--wait",
        "0",
    )
    assert done.returncode == 1, done.stderr
    assert "finished at" not in done.stderr, done.stderr
    assert "cannot connect" in done.stderr, done.stderr  # its nodes are gone all the same
    assert "nothing injected" in done.stderr and "program mine.pl refused" not in done.stderr
    assert "its driver may have stopped" in done.stderr and "dfrl collect" in done.stderr
