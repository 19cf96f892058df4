"""Process exit with live agent threads (blocked in get_qtable, busy, sleeping) is clean:
each case runs in its own interpreter, since embedded Prolog exists once per process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).with_name("exit_script.py")
ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("mode, code", [("atexit", 0), ("close", 0), ("raise", 3)])
def test_exit_with_live_agent_threads(mode: str, code: int) -> None:
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), mode], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == code, proc.stderr
    assert "READY" in proc.stdout
    for bad in ("Segmentation", "Assertion", "Failed to stop", "Traceback", "core dumped"):
        assert bad not in proc.stderr, proc.stderr
    if mode == "close":
        assert "LEFT []" in proc.stdout


def test_stop_threads_never_joins_a_detached_thread_as_it_exits() -> None:
    """600 closes with three detached threads each, aborted by bridge_stop_threads/3: all
    return and leave no thread. Control: with the join of detached threads that the bridge
    had before, this hung (SWI-Prolog 9.0.4 deadlocks) in 5 of 5 runs within 20 s."""
    script = Path(__file__).with_name("stop_detached_script.pl")
    proc = subprocess.run(["swipl", str(script), "600"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-2000:]
    # every close aborted its three threads (a loop that aborted nothing would prove nothing)
    assert "done 600 left 0 aborted 1800" in proc.stdout, proc.stdout
