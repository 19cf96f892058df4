"""``dfrl bench round`` on real processes, tiny budget."""
from __future__ import annotations

import shutil

import pytest

from dfrl.experiments.bench.round import bench

pytestmark = pytest.mark.skipif(shutil.which("swipl") is None, reason="needs swipl")


def test_bench_round_smoke() -> None:
    r = bench(entries=400, actions=4, robots=3, rounds=3, warmup=1)
    assert r["rounds"] == 3 and r["hops"] == 4, r
    assert r["all_equal_rounds"] == r["total_rounds"] == 4, r
    assert 0 < r["median_ms"] < 5000
