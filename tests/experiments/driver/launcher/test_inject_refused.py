"""A program a node refuses is not injected (issue 20): ``dfrl inject`` of a program with a
syntax error, or one the sandbox refuses, exits 1 saying "refused" and why (the syntax error
with file:line), stores nothing in ``programs/``, the driver never says "injected", and a
later join is not refused because of it. Real run, real ``dfrl inject`` processes.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from dfrl.experiments.driver.launcher import Results, inject_method, join_robot
from dfrl.experiments.processes import find_swipl
from dfrl.platform_pl import DFRL_AGENT_DIR

from .helpers import dfrl_inject, run_in_thread, small_config, stop_agents, wait_rounds

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

MEDIAN = DFRL_AGENT_DIR / "examples" / "median_method.pl"


def test_refused_programs_are_not_injected(tmp_path: Path) -> None:
    out = tmp_path / "run"
    broken = tmp_path / "broken_method.pl"
    broken.write_text("broken_ok(1).\nbroken(X) :- X = .\n", encoding="utf-8")
    unsafe = tmp_path / "unsafe_method.pl"
    unsafe.write_text(
        ":- initialization(shell('touch /tmp/dfrl_unsafe_marker')).\n", encoding="utf-8"
    )
    # a long run (300 rounds, ~100 s), ended by a stop command once the commands were tried
    cfg = small_config(iterations=30000, respite=100, rtf=20.0, timeout_s=300)
    t, box = run_in_thread(cfg, out)
    wait_rounds(out, "fed_qlearning", 2)

    bad = dfrl_inject(out, broken, "broken")
    assert bad.returncode == 1, bad.stderr
    assert "refused" in bad.stderr and "broken_method.pl:2:" in bad.stderr, bad.stderr
    assert "Syntax error" in bad.stderr, bad.stderr
    refused = dfrl_inject(out, unsafe, "unsafe")
    assert refused.returncode == 1, refused.stderr
    assert "refused" in refused.stderr and "Refused mobile code" in refused.stderr, refused.stderr
    assert not (out / "programs").exists()

    info = join_robot(out, "r3", "r2")  # not refused because of a bad program
    assert info["robot"] == "r3"
    assert inject_method(out, MEDIAN, "median") == {"fed_qlearning": "applied"}
    assert sorted(p.name for p in (out / "programs").iterdir()) == ["median_method.pl"]

    stop_agents(out)
    t.join(timeout=180)
    res: Results = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert res.ok, (out / "summary.md").read_text()
    said = (out / "summary.md").read_text()
    assert "broken_method" not in said and "unsafe_method" not in said
