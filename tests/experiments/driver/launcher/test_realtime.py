"""The shipped ``realtime`` config (5 robots, rtf 1.0, async, 4 rounds) completes every round
(issue 8: a node quiet past the worker pool's idle timeout used to drop the agent after
round 1). About 2.5 minutes of wall time: slow."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.config import ExperimentConfig, resolve_config
from dfrl.experiments.driver.launcher import run

from .helpers import diagnose


@pytest.mark.slow
def test_realtime_config_completes_all_its_rounds(tmp_path: Path) -> None:
    cfg = ExperimentConfig.load(resolve_config("realtime"))
    t0 = time.monotonic()
    res = run(cfg, tmp_path, progress=None)
    wall = time.monotonic() - t0
    detail = diagnose(tmp_path) + f"\nwall {wall:.0f} s"
    assert res.ok and res.complete, detail
    assert sorted(int(r["round"]) for r in res.rounds) == list(range(1, cfg.rounds + 1)), detail
    assert all(r["all_equal"] for r in res.rounds), detail
    assert all(r["visited"].split() == [s.id for s in cfg.robots] for r in res.rounds), detail
    assert res.faults is not None and not res.faults.lost and not res.faults.skips, detail
