"""Smoke test of ``dfrl bench bridge`` with a tiny budget (own process: it opens a node)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_bench_bridge_json() -> None:
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "experiments",
            "bench",
            "bridge",
            "--entries",
            "400",
            "--repeats",
            "5",
            "--warmup",
            "1",
            "--bodies",
            "3",
            "--json",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report["entries"] == 400 and report["shape"] == [100, 4]
    assert report["median_ms"] > 0 and report["p90_ms"] >= report["median_ms"]
    assert set(report["codecs"]) == {"fts", "text"}
    assert all(r["bit_exact"] and r["pairs"] == 5 for r in report["codecs"].values())
