"""Acting on a running experiment from outside: injecting a method (``dfrl inject``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.driver.launcher import Results, inject_method
from dfrl.platform_pl import DFRL_AGENT_DIR

from .helpers import rounds_csv, run_in_thread, small_config, wait_rounds
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


MEDIAN = DFRL_AGENT_DIR / "examples" / "median_method.pl"


def test_inject_method_into_running_experiment(tmp_path: Path) -> None:
    # rtf 20: 100 iterations take 0.32 s, so the run lasts long enough to inject into
    cfg = small_config(iterations=2000, respite=100, rtf=20.0)
    t, box = run_in_thread(cfg, tmp_path)
    wait_rounds(tmp_path, "fed_qlearning", 2)
    assert inject_method(tmp_path, MEDIAN, "median") == {"fed_qlearning": "applied"}
    t.join(timeout=120)
    assert not t.is_alive()
    res: Results = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert res.ok
    methods = [r["method"] for r in rounds_csv(tmp_path)]
    assert len(methods) == 20
    first = methods.index("median")
    assert 2 <= first < 19
    assert set(methods[:first]) == {"average"} and set(methods[first:]) == {"median"}
    assert all(r["all_equal"] == "true" for r in rounds_csv(tmp_path))
    # the connection the injection pooled at r1 did not keep a Prolog thread alive at exit
    for err in (tmp_path / "logs").glob("r*.err"):
        assert "still running after close" not in err.read_text(), err


FAILING = Path(__file__).parent / "failing_method.pl"


def test_inject_refused_method_and_failing_method(tmp_path: Path) -> None:
    """An injected method the agent does not know is refused (after the agent said so); one
    that fails at run time is replaced, in the round it failed, by the method the agent falls
    back to: the round is done again and every table written, and it stays loud: the run is
    not ok, rounds.csv and the summary say which round's method failed and with what the
    round was done."""
    cfg = small_config(iterations=1600, respite=100, rtf=20.0)
    t, box = run_in_thread(cfg, tmp_path)
    wait_rounds(tmp_path, "fed_qlearning", 2)
    with pytest.raises(ExperimentError, match="ignored method trimmed.*unknown method"):
        inject_method(tmp_path, MEDIAN, "trimmed")
    assert inject_method(tmp_path, FAILING, "failing") == {"fed_qlearning": "applied"}
    t.join(timeout=120)
    res: Results = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert not res.ok and not res.complete
    rows = rounds_csv(tmp_path)
    failed = [r for r in rows if r["error"]]
    assert failed and all(r["failed_method"] == "failing" for r in failed)
    assert all(r["method"] == "average" for r in failed), failed
    assert all(r["all_equal"] and r["visited"] == "r1 r2" for r in failed), failed
    assert all("aggregate_step(failing) failed" in r["error"] for r in failed)
    # control: the rounds around it name no failed method
    assert all(r["failed_method"] == "" for r in rows if not r["error"])
    summary = (tmp_path / "summary.md").read_text()
    assert f"FAILED: fed_qlearning round {failed[0]['round']} (failing)" in summary
    assert "done again with average" in summary
    assert "METHOD FAILED" in summary
    assert all((tmp_path / "tables" / f"{r}.npy").is_file() for r in ("r1", "r2"))
