"""``metrics.csv``: merging the per-robot files and reading the curves back."""
from __future__ import annotations

from pathlib import Path

from dfrl.experiments.driver.results.metrics import merge_metrics, read_metrics


def test_merge_and_read_metrics(tmp_path: Path) -> None:
    for robot in ("r1", "r2"):
        (tmp_path / f"metrics_{robot}.csv").write_text(
            "robot,iteration,q_sum,cumulative_reward,collisions\n"
            f"{robot},1,0.5,1.0,0\n{robot},2,0.75,2.0,1\n{robot},3,0.", encoding="utf-8")
    merge_metrics(tmp_path, ["r1", "r2", "r9"])
    curves = read_metrics(tmp_path / "metrics.csv")
    assert list(curves) == ["r1", "r2"]
    assert curves["r2"]["q_sum"].tolist() == [0.5, 0.75]       # torn last line dropped
    assert curves["r1"]["collisions"].tolist() == [0, 1]
