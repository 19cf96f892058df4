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

from dfrl.experiments.tools.bench import faults, faults_cases
from dfrl.experiments.tools.bench.faults_cases import CASES, Case, Expectation
from dfrl.experiments.tools.bench.faults_federation import Plan
from dfrl.experiments.tools.netns import leftover_namespaces, unavailable

WHY = unavailable()
needs_namespaces = pytest.mark.skipif(WHY is not None, reason=WHY or "")

#: kill_mid_hop on 3 hosts, 6 rounds (about 30 s here): the fault strikes after round 3
QUICK = Case(
    "kill_mid_hop",
    CASES["kill_mid_hop"].what,
    CASES["kill_mid_hop"].expect,
    lambda hosts: Plan(hosts=hosts, iterations=600, timeout_s=90.0),
    CASES["kill_mid_hop"].act,
)


def _lie(summary: str) -> str:
    """summary.md as a run that hid its fault would write it."""
    text = summary.replace("## Faults: federation INCOMPLETE", "## Faults: federation complete")
    return re.sub(r"^- (MISSED|LOST).*\n", "", text, flags=re.M)


@needs_namespaces
def test_a_robot_host_killed_mid_hop_is_measured_and_judged(tmp_path: Path) -> None:
    seen: list[dict] = []
    [f] = faults.run(
        ["kill_mid_hop"],
        runs=1,
        hosts=3,
        keep=tmp_path,
        on_fault=seen.append,
        cases={"kill_mid_hop": QUICK},
    )
    assert seen == [f]
    json.dumps(f)  # the CLI prints it as JSON
    [r] = f["per_run"]
    detail = json.dumps(r, indent=1)
    assert f["passed"] and r["passed"] and r["problems"] == [], detail
    assert r["victim"] == "r2" and r["absent"].get("r2", 0) >= 1, detail
    assert (r["rounds_done"], r["rounds_planned"]) == (6, 6), detail
    assert r["tables_identical"] and r["truthful"], detail
    assert r["verdict"] == "INCOMPLETE" and r["exit_status"] == 1, detail
    assert any(
        s.startswith(("- MISSED rounds: r2", "- LOST robot r2")) for s in r["summary_says"]
    ), detail
    assert r["recovery_s"] is not None, detail
    # 0 when the kill lands as a round completes (the round logged within 5 ms of it)
    assert 0 <= r["recovery_s"] <= QUICK.expect.recovery_bound_s, detail
    assert [a["what"].split(" of ")[0] for a in r["actions"][:2]] == [
        "driver started",
        "kill -9",
    ], detail
    assert f["median"]["recovery_s"] == r["recovery_s"]
    assert not leftover_namespaces(f"dfrl{os.getpid() % 100000}-")  # the lab's tag

    # the control: the same files, judged with a lying verdict and an unmet expectation
    out = next(tmp_path.glob("kill_mid_hop-1")) / "driver" / "out"
    rows = faults.read_rows(out)
    summary = (out / "summary.md").read_text(encoding="utf-8")
    t_fault, t0 = r["fault_time"], r["fault_time"] - r["fault_at_s"]
    robots = ["r1", "r2", "r3"]
    honest = faults.measure(rows, summary, 1, t_fault, t0, robots, 6, "r2")
    assert {k: honest[k] for k in ("recovery_s", "truthful", "absent")} == {
        k: r[k] for k in ("recovery_s", "truthful", "absent")
    }
    assert honest["truthful"], honest
    lying = faults.measure(rows, _lie(summary), 0, t_fault, t0, robots, 6, "r2")
    assert not lying["truthful"] and lying["verdict"] == "complete", lying
    assert any("untruthful" in p for p in faults.judge(lying, QUICK.expect))
    assert any("exit status 0" in p for p in lying["truth_problems"])
    assert any("does not name r2" in p for p in lying["truth_problems"])
    unmet = faults.judge(honest, Expectation(rejoin=True))
    assert unmet == ["r2 was not visited again after its absence"], unmet


def _row(n: int, end: float, visited: str, digests: dict[str, str], error: str = "") -> dict:
    return {
        "round": str(n),
        "end": str(end),
        "visited": visited,
        "error": error,
        "all_equal": "true" if len(set(digests.values())) == 1 else "false",
        **{f"digest_{r}": digests.get(r, "") for r in ("r1", "r2", "r3")},
    }


def test_measure_on_hand_made_rounds() -> None:
    # Prepare: 5 planned rounds; the fault at t=102.5; r2 absent from rounds 3 and 4, back in
    # 5; round 2's r3 share not on record; round 4 a failed method (no table)
    rows = [
        _row(1, 101.0, "r1 r2 r3", {"r1": "a", "r2": "a", "r3": "a"}),
        _row(2, 102.0, "r1 r2 r3", {"r1": "b", "r2": "b", "r3": "missing"}),
        _row(3, 106.0, "r1 r3", {"r1": "c", "r3": "c"}),
        _row(4, 107.0, "r1 r3", {}, error="aggregate_step(failing) failed"),
        _row(5, 108.0, "r1 r2 r3", {"r1": "d", "r2": "d", "r3": "d"}),
    ]
    honest = (
        "## Faults: federation INCOMPLETE\n- METHOD FAILED in 1 round(s)\n"
        "- MISSED rounds: r2 missed 2 round(s)\n"
    )
    # Execute
    m = faults.measure(rows, honest, 1, 102.5, 100.0, ["r1", "r2", "r3"], 5, "r2")
    # Assert: hand-computed figures
    assert (m["fault_at_s"], m["recovery_s"], m["longest_stall_s"]) == (2.5, 3.5, 4.0)
    assert m["normal_gap_s"] == 1.0
    assert (m["rounds_done"], m["rounds_planned"], m["rounds_failed"]) == (4, 5, 1)
    assert m["tables_identical"] and m["rounds_unverified"] == 1
    assert m["absent"] == {"r2": 1} and m["rejoined"] is True
    assert m["truthful"], m["truth_problems"]
    assert faults.judge(m, Expectation(max_rounds_lost=1, rejoin=True, method_failed=True)) == []
    # controls: differing tables, a verdict that hides the fault, an unreported failed method
    rows[4]["digest_r3"] = "e"
    differ = faults.measure(rows, honest, 1, 102.5, 100.0, ["r1", "r2", "r3"], 5, "r2")
    assert not differ["tables_identical"]
    assert "a completed round left differing tables" in faults.judge(
        differ, Expectation(max_rounds_lost=1)
    )
    hidden = faults.measure(
        rows, "## Faults: federation complete\n", 0, 102.5, 100.0, ["r1", "r2", "r3"], 5, "r2"
    )
    assert len(hidden["truth_problems"]) == 4, hidden["truth_problems"]
    assert faults.judge(hidden, Expectation(stall_bound_s=3.0, max_rounds_lost=1))[:2] == [
        "4.0 s between two completed rounds (bound 3 s)",
        "a completed round left differing tables",
    ]


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


#: issue 33's cut of the resting agent's host, shortened: a 15 s cut after round 3 of 8
SHORT_CUT = Case(
    "cut_agent_host_30",
    CASES["cut_agent_host_30"].what,
    CASES["cut_agent_host_30"].expect,
    lambda hosts: Plan(hosts=hosts, iterations=800, timeout_s=120.0),
    faults_cases._cut_for(15, "agent"),
)


@pytest.mark.slow
@needs_namespaces
def test_a_cut_of_the_resting_agents_host_is_judged_by_the_history(tmp_path: Path) -> None:
    # Execute: one run on 3 hosts that share no disk
    [f] = faults.run(
        ["cut_agent_host_30"],
        runs=1,
        hosts=3,
        keep=tmp_path,
        cases={"cut_agent_host_30": SHORT_CUT},
    )
    [r] = f["per_run"]
    detail = json.dumps(r, indent=1)
    json.dumps(f)
    # Assert: the fields issue 33 asks for, present and sane (not whether the platform passes)
    assert "error" not in r, detail
    assert r["itinerary"] == "chain" and r["no_shared_disk"] is True
    assert r["rests_on"] in ("r1", "r2", "r3") and r["holder"] in ("r1", "r2", "r3")
    assert r["victim"] == r["rests_on"] != r["holder"], detail
    h = r["history"]
    assert h["ok"] in (True, False), detail
    assert set(h["counts"]) <= {"doubled_write", "epoch_regressed", "stale_epoch", "split_round"}, (
        detail
    )
    assert h["ok"] == (sum(h["counts"].values()) == 0), detail
    assert isinstance(r["exit_status"], int) and r["verdict"] in ("complete", "INCOMPLETE")
    assert set(r["summary_missed"]) | set(r["summary_lost"]) <= {"r1", "r2", "r3"}
    assert isinstance(r["any_lost"], bool) and r["any_lost"] == bool(r["summary_lost"])
    assert r["longest_write_gap_s"] is not None and r["longest_write_gap_s"] > 0, detail
    assert r["write_gap_bound_s"] > faults_cases.SKIP_AFTER_S, detail
    assert [a["what"] for a in r["actions"]][:2] == [
        "driver started",
        f"link of h{r['victim'][1:]} ({r['victim']}) cut",
    ], detail
    # every robot's shares came from its own host's disk, copied out after the run
    for rid in ("r1", "r2", "r3"):
        assert (tmp_path / "cut_agent_host_30-1" / "history" / f"shares_{rid}.csv").is_file()
    assert not leftover_namespaces(f"dfrl{os.getpid() % 100000}-")


def test_issue_33_figures_on_hand_made_files() -> None:
    # Prepare: what the robots wrote (round 3 written twice, by two epochs) and a summary
    shares = {
        "r1": [
            {"round": "1", "wall_time": "10.0"},
            {"round": "2", "wall_time": "11.5"},
            {"round": "3", "wall_time": "19.5"},
            {"round": "3", "wall_time": "20.0"},
        ],
        "r2": [{"round": "1", "wall_time": "10.2"}, {"round": "", "wall_time": "12.0"}],
    }
    summary = (
        "## Faults: federation INCOMPLETE\n- MISSED rounds: r2 missed 2 round(s)\n"
        "- LOST robot r3: its host stopped answering\n"
    )
    # Execute, Assert: round times 10.2, 11.5, 20.0: gaps 1.3 and 8.5
    assert faults.write_gaps(shares) == (8.5, 4.9)
    assert faults.write_gaps({"r1": []}) == (None, None)
    assert faults.named_in_summary(summary) == {"missed": ["r2"], "lost": ["r3"]}
    assert faults_cases.holder_of(("r1", "r2", "r3")) == "r2"
    with pytest.raises(ValueError, match="no holder"):
        faults_cases.holder_of(("r1",))
    m = {
        "rounds_planned": 5,
        "rounds_done": 5,
        "recovery_s": 1.0,
        "longest_stall_s": 2.0,
        "tables_identical": True,
        "truthful": True,
        "victim": None,
        "absent": {},
        "rounds_failed": 0,
        "verdict": "complete",
        "exit_status": 0,
        "history": {"ok": False, "counts": {"doubled_write": 2, "stale_epoch": 0}},
        "longest_write_gap_s": 8.5,
        "write_gap_bound_s": 5.5,
    }
    assert faults.judge(m, Expectation(victim_misses=False, gap_within_skip=True)) == [
        "the robots' shares break the history: 2 doubled_write",
        "8.5 s between two rounds written on the robots (bound: skip time 4 s + one round = 5.5 s)",
    ]
    assert faults.judge(m, Expectation(victim_misses=False, incomplete=True))[-1].startswith(
        "verdict complete and exit status 0 after a robot host was cut"
    )
