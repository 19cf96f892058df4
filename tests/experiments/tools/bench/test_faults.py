"""``dfrl bench faults`` end to end on real ``dfrl robot`` hosts in network namespaces: one
cheap fault once (a robot host killed -9 as the agent hops to it), its JSON checked; the
control judges the same run's files again with a verdict that lies (exit 0 and "federation
complete") and with an expectation it cannot meet (the dead robot visited again), and both
must fail. Skipped with the reason where namespaces cannot be made."""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from dfrl.experiments.tools.bench import faults
from dfrl.experiments.tools.bench.faults_cases import CASES, Case, Expectation
from dfrl.experiments.tools.bench.faults_federation import Plan
from dfrl.experiments.tools.netns import leftover_namespaces, unavailable

WHY = unavailable()
needs_namespaces = pytest.mark.skipif(WHY is not None, reason=WHY or "")

#: kill_mid_hop on 3 hosts, 6 rounds (about 30 s here): the fault strikes after round 3
QUICK = Case("kill_mid_hop", CASES["kill_mid_hop"].what, CASES["kill_mid_hop"].expect,
             lambda hosts: Plan(hosts=hosts, iterations=600, timeout_s=90.0),
             CASES["kill_mid_hop"].act)


def _lie(summary: str) -> str:
    """summary.md as a run that hid its fault would write it."""
    text = summary.replace("## Faults: federation INCOMPLETE", "## Faults: federation complete")
    return re.sub(r"^- (MISSED|LOST).*\n", "", text, flags=re.M)


@needs_namespaces
def test_a_robot_host_killed_mid_hop_is_measured_and_judged(tmp_path: Path) -> None:
    seen: list[dict] = []
    [f] = faults.run(["kill_mid_hop"], runs=1, hosts=3, keep=tmp_path,
                     on_fault=seen.append, cases={"kill_mid_hop": QUICK})
    assert seen == [f]
    json.dumps(f)                                    # the CLI prints it as JSON
    [r] = f["per_run"]
    detail = json.dumps(r, indent=1)
    assert f["passed"] and r["passed"] and r["problems"] == [], detail
    assert r["victim"] == "r2" and r["absent"].get("r2", 0) >= 1, detail
    assert (r["rounds_done"], r["rounds_planned"]) == (6, 6), detail
    assert r["tables_identical"] and r["truthful"], detail
    assert r["verdict"] == "INCOMPLETE" and r["exit_status"] == 1, detail
    assert any(s.startswith(("- MISSED rounds: r2", "- LOST robot r2")) for s in
               r["summary_says"]), detail
    assert 0 < r["recovery_s"] <= QUICK.expect.recovery_bound_s, detail
    assert [a["what"].split(" of ")[0] for a in r["actions"][:2]] == ["driver started",
                                                                     "kill -9"], detail
    assert f["median"]["recovery_s"] == r["recovery_s"]
    assert not leftover_namespaces(f"dfrl{os.getpid() % 100000}-")   # the lab's tag

    # the control: the same files, judged with a lying verdict and an unmet expectation
    out = next(tmp_path.glob("kill_mid_hop-1")) / "driver" / "out"
    rows = faults.read_rows(out)
    summary = (out / "summary.md").read_text(encoding="utf-8")
    t_fault, t0 = r["fault_time"], r["fault_time"] - r["fault_at_s"]
    robots = ["r1", "r2", "r3"]
    honest = faults.measure(rows, summary, 1, t_fault, t0, robots, 6, "r2")
    assert {k: honest[k] for k in ("recovery_s", "truthful", "absent")} == \
        {k: r[k] for k in ("recovery_s", "truthful", "absent")}
    assert honest["truthful"], honest
    lying = faults.measure(rows, _lie(summary), 0, t_fault, t0, robots, 6, "r2")
    assert not lying["truthful"] and lying["verdict"] == "complete", lying
    assert any("untruthful" in p for p in faults.judge(lying, QUICK.expect))
    assert any("exit status 0" in p for p in lying["truth_problems"])
    assert any("does not name r2" in p for p in lying["truth_problems"])
    unmet = faults.judge(honest, Expectation(rejoin=True))
    assert unmet == ["r2 was not visited again after its absence"], unmet


def test_bad_requests_are_refused_before_any_host_starts(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown fault.*nope.*known: restart_robot"):
        faults.run(["nope"], keep=tmp_path)
    with pytest.raises(ValueError, match="--hosts must be 2 to 5"):
        faults.run(["kill_mid_hop"], hosts=9, keep=tmp_path)
    with pytest.raises(ValueError, match="--runs must be at least 1"):
        faults.run(["kill_mid_hop"], runs=0, keep=tmp_path)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
@needs_namespaces
@pytest.mark.parametrize("name", ["restart_robot", "failing_method", "kill_driver"])
def test_other_faults_once(tmp_path: Path, name: str) -> None:
    [f] = faults.run([name], runs=1, hosts=3, keep=tmp_path)
    assert f["passed"], json.dumps(f, indent=1)
