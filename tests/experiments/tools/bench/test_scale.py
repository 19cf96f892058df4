"""``dfrl bench scale`` on a tiny budget: real robot processes, the real agent."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def test_scale_benchmark_reports_each_point() -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "dfrl",
            "bench",
            "scale",
            "--robots",
            "2",
            "3",
            "--iterations",
            "200",
            "--respite",
            "100",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    r = json.loads(out.stdout)
    assert [p["robots"] for p in r["points"]] == [2, 3]
    for p in r["points"]:
        assert p["rounds"] == p["rounds_planned"] == p["rounds_all_equal"] == 2
        assert 20 < p["rss_median_mb"] < 300 and p["round_median_ms"] > 0
    assert r["growth"][0]["round_ratio_vs_linear"] == 1.0
