"""``dfrl bench sim`` with a tiny budget."""
from __future__ import annotations

import json

import pytest

from dfrl.experiments.cli import main


def test_bench_sim_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "sim", "--steps", "100", "--robots", "1", "2", "--warmup", "5",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["steps_per_s"] > 0 and out["realtime_factor"] == pytest.approx(
        out["steps_per_s"] * 0.064, rel=0.01)
    assert [r["robots"] for r in out["scaling"]] == [1, 2]
