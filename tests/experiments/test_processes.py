"""One kill policy and one ``swipl`` lookup (experiments/processes.py), on real processes."""

from __future__ import annotations

import os
import subprocess
import time

import pytest

from dfrl.experiments import processes
from dfrl.experiments.errors import ExperimentError


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is not alive
    with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
        return stat.read().split(") ", 1)[1][0] != "Z"


def test_stop_kills_a_child_that_ignores_sigterm_and_its_grandchild() -> None:
    proc = processes.start(
        ["sh", "-c", "trap '' TERM; sleep 60 & echo $!; wait"], stdout=subprocess.PIPE
    )
    assert proc.stdout is not None
    grandchild = int(proc.stdout.readline())
    began = time.monotonic()
    code = processes.stop(proc, grace_s=0.5)
    took = time.monotonic() - began
    assert code == -9  # SIGTERM was ignored, SIGKILL ended it
    assert 0.4 < took < 5
    deadline = time.monotonic() + 5
    while _alive(grandchild) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(grandchild)


def test_stop_is_quick_for_a_child_that_obeys_sigterm() -> None:
    proc = processes.start(["sleep", "60"])
    began = time.monotonic()
    assert processes.stop(proc, grace_s=5) == -15
    assert time.monotonic() - began < 2


def test_wait_or_stop_tells_exit_from_kill() -> None:
    assert processes.wait_or_stop(processes.start(["true"]), timeout_s=5) is True
    assert (
        processes.wait_or_stop(processes.start(["sleep", "60"]), timeout_s=0.2, grace_s=1) is False
    )


def test_one_error_when_swipl_is_missing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PATH", "/nonexistent")
    assert processes.find_swipl() is None
    with pytest.raises(ExperimentError, match=r"swipl is not installed \(run scripts/setup.sh\)"):
        processes.swipl()


def test_a_missing_executable_is_an_experiment_error() -> None:
    with pytest.raises(ExperimentError, match="could not start /nonexistent/x"):
        processes.start(["/nonexistent/x"])
