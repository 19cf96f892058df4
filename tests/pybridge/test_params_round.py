"""A dFRL agent federates parameter vectors between two robots of a robot process
(params_round_script.py, in a process of its own: the platform runs once per process)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = Path(__file__).with_name("params_round_script.py")


def test_two_robots_hold_the_same_fedavg_after_every_round() -> None:
    proc = subprocess.run(
        [sys.executable, str(SCRIPT)], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["moved"], out
    rounds = [e for e in out["events"] if e["event"] == "round"]
    assert [e["round"] for e in rounds] == [1, 2], out["events"]
    for e in rounds:
        assert e["visited"] == ["r1", "r2"] and e["skipped"] == [] and "error" not in e, e
        assert e["method"] == "average" and e["hops"] >= 2
    assert out["sets"] == {"r1": 2, "r2": 2}
    # every robot holds the same parameters, bit for bit what FedAvg by hand gives
    assert out["digests"]["r1"] == out["digests"]["r2"] == out["expected"]["r1"], out
    for bad in ("Warning", "ERROR", "Traceback", "Segmentation"):
        assert bad not in proc.stderr, proc.stderr
