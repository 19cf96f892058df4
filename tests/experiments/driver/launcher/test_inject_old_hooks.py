"""A method written for the old hook module is refused by ``dfrl inject`` with the new name of
the very predicate it uses (issue 36): before, the node's reason stayed on the node and the
command said only "it may not define dfrl_agent:aggregate_init(...)" or "it calls
dfrl_agent:aggregate_step/4, which is not part of the agent API". A real run, real
``dfrl inject`` processes; the control: the same method written for dfrl_aggregation is
applied."""

from __future__ import annotations

from pathlib import Path

import pytest

from dfrl.experiments.driver.launcher import Results
from dfrl.experiments.processes import find_swipl

from .helpers import dfrl_inject, run_in_thread, small_config, stop_agents, wait_rounds

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

#: An old method: it defines a hook of dfrl_agent (its head).
OLD_HEAD = "dfrl_agent:aggregate_init(oldhead, qtable(_, V), V).\n"
#: A method of the new module that still calls a hook through the old one (its body).
OLD_CALL = (
    "dfrl_aggregation:aggregate_init(oldcall, T, A) :- "
    "dfrl_aggregation:aggregate_init(average, T, A).\n"
    "dfrl_aggregation:aggregate_step(oldcall, A0, T, A) :- "
    "dfrl_agent:aggregate_step(average, A0, T, A).\n"
    "dfrl_aggregation:aggregate_final(oldcall, A, T) :- "
    "dfrl_aggregation:aggregate_final(average, A, T).\n"
)
#: The control: that method as it is written now.
NEW_CALL = OLD_CALL.replace("dfrl_agent:", "dfrl_aggregation:").replace("oldcall", "newcall")


def test_an_old_hook_is_pointed_to_its_new_module(tmp_path: Path) -> None:
    out = tmp_path / "run"
    programs = {}
    for name, text in (("old_head", OLD_HEAD), ("old_call", OLD_CALL), ("new_call", NEW_CALL)):
        programs[name] = tmp_path / f"{name}.pl"
        programs[name].write_text(text, encoding="utf-8")
    cfg = small_config(iterations=8000, respite=100, rtf=20.0, timeout_s=300)  # ~26 s
    t, box = run_in_thread(cfg, out)
    try:
        wait_rounds(out, "fed_qlearning", 1)
        head = dfrl_inject(out, programs["old_head"], "oldhead")
        assert head.returncode == 1, head.stderr
        assert (
            "it uses dfrl_agent:aggregate_init/3, which is dfrl_aggregation:aggregate_init/3 now"
        ) in head.stderr, head.stderr
        call = dfrl_inject(out, programs["old_call"], "oldcall")
        assert call.returncode == 1, call.stderr
        assert (
            "it uses dfrl_agent:aggregate_step/4, which is dfrl_aggregation:aggregate_step/4 now"
        ) in call.stderr, call.stderr
        new = dfrl_inject(out, programs["new_call"], "newcall")
        assert new.returncode == 0, new.stderr
        assert "method newcall applied by fed_qlearning" in new.stdout
    finally:
        stop_agents(out)
        t.join(timeout=240)
    res: Results = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert res.ok, (out / "summary.md").read_text()
