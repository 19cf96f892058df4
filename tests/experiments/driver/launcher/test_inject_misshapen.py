"""An injected method whose finished aggregate is no table of the carried shape (here the
values wrapped in a term) is a method failure, found by the agent before it writes: the
round is done again with the method it falls back to, every table is written, sync robots
are not left waiting (all rounds done), and nothing echoes the whole value into the logs.
Before the check every write was refused and the agent stopped with a type error. Real run."""

from __future__ import annotations

from pathlib import Path

import pytest

from dfrl.experiments.driver.launcher import Results, inject_method
from dfrl.experiments.processes import find_swipl

from .helpers import rounds_csv, run_in_thread, small_config, wait_rounds

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

MISSHAPEN = Path(__file__).parent / "misshapen_method.pl"


def test_misshapen_final_aggregate_is_a_method_failure(tmp_path: Path) -> None:
    cfg = small_config(iterations=1600, respite=100, rtf=20.0)
    t, box = run_in_thread(cfg, tmp_path)
    wait_rounds(tmp_path, "fed_qlearning", 2)
    assert inject_method(tmp_path, MISSHAPEN, "misshapen") == {"fed_qlearning": "applied"}
    t.join(timeout=120)
    res: Results = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    rows = rounds_csv(tmp_path)
    assert len(rows) == 16, [r["round"] for r in rows]
    failed = [r for r in rows if r["error"]]
    assert failed and all(r["failed_method"] == "misshapen" for r in failed)
    assert all("aggregate_final(misshapen)" in r["error"] for r in failed), failed
    assert all(r["method"] == "average" and r["visited"] == "r1 r2" for r in failed), failed
    assert all(r["all_equal"] == "true" and r["skipped"] == "" for r in rows), rows
    assert not res.ok and not res.complete  # loud: a method failed
    summary = (tmp_path / "summary.md").read_text()
    assert "16 of 16 planned rounds done" in summary, summary
    assert "done again with average" in summary, summary
    assert (tmp_path / "rounds.csv").stat().st_size < 8000
    for err in (tmp_path / "logs").glob("*.err"):
        assert err.stat().st_size < 4000, err.read_text()[:2000]
