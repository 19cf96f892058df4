"""Faults: a federation of ``dfrl robot`` hosts in network namespaces, one fault at a time.

Each run builds its own :class:`~dfrl.experiments.tools.netns.Lab` (N robot hosts and a
driver host on a private bridge), starts a short sync experiment across it
(:mod:`.faults_federation`), does one fault of :mod:`.faults_cases` (kill -9 a robot host
and restart it, kill it mid-hop, kill the host the agent rests on, cut a link for 30 s or
90 s, kill the driver then ``dfrl collect``, inject a failing method) and reads what the run
wrote: ``rounds.csv``, ``summary.md`` and the exit status of the command that gave the
verdict. Per run it reports the actions and their times, the recovery time (fault -> next
completed round), the longest gap between two completed rounds, rounds done of planned,
whether every completed round left identical tables, whether the verdict and exit status
told the truth, and pass/fail against the case's stated expectation. The lab is closed (every
process killed, every namespace deleted) after each run, on an exception or Ctrl-C too.

The hosts share no disk (each has a private tmpfs over the run's folder, in a mount namespace
of its own: :mod:`.faults_federation`). Once the case is over, this process copies every
host's folder out of its host (through the host's mount namespace) and judges each robot's
``shares_<robot>.csv``, as the robot's own host wrote it, with the history checker
(:func:`~dfrl.experiments.driver.results.history.check_history`: doubled writes, epochs gone
back, stale epochs, split rounds); it also reports the longest gap between rounds as the
robots wrote them (the driver may not have seen every round), the robots summary.md names as
missing rounds and those it calls LOST.

Needs root and ``ip`` (:func:`~dfrl.experiments.tools.netns.unavailable` says why not).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import re
import shutil
import statistics
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.results.history import HistoryInputError, check_history
from dfrl.experiments.tools.bench.faults_cases import CASES, SKIP_AFTER_S, Acted, Case, Expectation
from dfrl.experiments.tools.bench.faults_federation import FaultBenchError, Federation
from dfrl.experiments.tools.netns import Lab

VERDICT_LINE = "## Faults: federation "
ITINERARIES = ("chain", "tree")


def read_rows(results: Path) -> list[dict[str, str]] | None:
    """``rounds.csv``'s rows (None when the run wrote none)."""
    p = results / "rounds.csv"
    if not p.is_file():
        return None
    return list(csv.DictReader(io.StringIO(p.read_text(encoding="utf-8"))))


def verdict_of(summary: str) -> str | None:
    """``complete`` or ``INCOMPLETE`` as summary.md's fault section says (None: no verdict)."""
    for line in summary.splitlines():
        if line.startswith(VERDICT_LINE):
            return line[len(VERDICT_LINE) :].strip()
    return None


def measure(
    rows: list[dict[str, str]],
    summary: str,
    exit_status: int,
    t_fault: float,
    t0: float,
    robots: list[str],
    planned: int,
    victim: str | None,
) -> dict[str, Any]:
    """The figures of one fault run from its rounds.csv rows and summary.md (see module doc).

    ``truth_problems`` lists where the verdict, the exit status or the summary's fault lines
    disagree with the rounds themselves: the federation was complete only if every planned
    round completed with every robot visited and no method failed.
    """
    done = sorted(
        (r for r in rows if not r["error"] or r.get("failed_method")), key=lambda r: float(r["end"])
    )
    failed = [r for r in rows if r["error"]]
    ends = [float(r["end"]) for r in done]
    after = [e for e in ends if e > t_fault]
    gaps = [b - a for a, b in zip(ends, ends[1:])]
    before = [b - a for a, b in zip(ends, ends[1:]) if b <= t_fault]
    absent: dict[str, list[int]] = {}
    for r in done:
        for rid in robots:
            if rid not in r["visited"].split():
                absent.setdefault(rid, []).append(int(r["round"]))
    n_done = len({int(r["round"]) for r in done})
    differing, unverified = _digest_checks(done, robots)
    rejoined = None
    if victim is not None:
        gone = absent.get(victim, [])
        rejoined = bool(gone) and any(
            victim in r["visited"].split() and int(r["round"]) > max(gone) for r in done
        )
    truth_complete = n_done >= planned and not failed and not absent
    verdict = verdict_of(summary)
    truth: list[str] = []
    if verdict is None:
        truth.append("summary.md gives no verdict" if summary else "no summary.md")
    elif (verdict == "complete") != truth_complete:
        truth.append(
            f"summary says federation {verdict}, but the federation was "
            f"{'complete' if truth_complete else 'not complete'}"
        )
    if (exit_status == 0) != truth_complete:
        truth.append(
            f"exit status {exit_status}, but the federation was "
            f"{'complete' if truth_complete else 'not complete'}"
        )
    for rid, missed in absent.items():
        if f"MISSED rounds: {rid} " not in summary and f"LOST robot {rid}:" not in summary:
            truth.append(f"summary does not name {rid}, absent from round(s) {missed[:10]}")
    if failed and "METHOD FAILED" not in summary:
        truth.append(f"{len(failed)} round(s) whose method failed, not reported")
    if n_done < planned and not failed and "MISSING rounds" not in summary:
        truth.append(f"{planned - n_done} planned round(s) not done, not reported")
    return {
        "fault_at_s": round(t_fault - t0, 2),
        "fault_time": round(t_fault, 3),
        "recovery_s": round(after[0] - t_fault, 2) if after else None,
        "longest_stall_s": round(max(gaps), 2) if gaps else None,
        "normal_gap_s": round(statistics.median(before), 2) if before else None,
        "rounds_done": n_done,
        "rounds_planned": planned,
        "rounds_failed": len(failed),
        "tables_identical": bool(done) and not differing,
        "rounds_unverified": unverified,
        "driver_all_equal_rounds": sum(r["all_equal"] == "true" for r in done),
        "absent": {rid: len(v) for rid, v in absent.items()},
        "victim": victim,
        "rejoined": rejoined,
        "verdict": verdict,
        "exit_status": exit_status,
        "summary_says": [
            ln.strip()
            for ln in summary.splitlines()
            if ln.startswith(
                (
                    "- MISSED",
                    "- LOST",
                    "- METHOD FAILED",
                    "- MISSING",
                    "- ENDED SHORT",
                    "- NOT LOGGED",
                    "- HISTORY VIOLATED",
                )
            )
        ],
        # rounds the agent's log lacks, rebuilt from the robots' shares by the driver
        "rounds_rebuilt": sum(r.get("reconstructed") == "true" for r in rows),
        "truthful": not truth,
        "truth_problems": truth,
    }


def _digest_checks(done: list[dict[str, str]], robots: list[str]) -> tuple[int, int]:
    """Completed rounds after which two visited robots held different tables, and rounds in
    which some visited robot's table is not on record (``missing``: its shares file never
    came back, e.g. from a host that died), so that equality cannot be checked there."""
    differing = unverified = 0
    for r in done:
        cells = [r.get(f"digest_{rid}", "") for rid in r["visited"].split() if rid in robots]
        known = {c for c in cells if c not in ("", "missing")}
        differing += len(known) > 1
        unverified += "missing" in cells
    return differing, unverified


def judge(m: dict[str, Any], expect: Expectation) -> list[str]:
    """Where the figures ``m`` of one run miss the case's expectation (empty: it passed)."""
    problems = []
    lost = m["rounds_planned"] - m["rounds_done"]
    if lost > expect.max_rounds_lost:
        problems.append(
            f"{lost} planned round(s) not completed (at most {expect.max_rounds_lost} expected)"
        )
    if m["recovery_s"] is None:
        problems.append("no round completed after the fault")
    elif m["recovery_s"] > expect.recovery_bound_s:
        problems.append(
            f"the next round completed {m['recovery_s']} s after the fault "
            f"(bound {expect.recovery_bound_s:g} s)"
        )
    if m["longest_stall_s"] is not None and m["longest_stall_s"] > expect.stall_bound_s:
        problems.append(
            f"{m['longest_stall_s']} s between two completed rounds (bound "
            f"{expect.stall_bound_s:g} s)"
        )
    if not m["tables_identical"]:
        problems.append("a completed round left differing tables")
    if not m["truthful"]:
        problems.append("untruthful: " + "; ".join(m["truth_problems"]))
    victim = m["victim"]
    if expect.victim_misses and not m["absent"].get(victim):
        problems.append(f"{victim} missed no round: the fault did not strike")
    if expect.rejoin and not m["rejoined"]:
        problems.append(f"{victim} was not visited again after its absence")
    if expect.method_failed and not m["rounds_failed"]:
        problems.append("no round's method failed: the injection did not strike")
    history = m.get("history")
    if expect.history_clean and history is not None:
        if history.get("ok") is None:
            problems.append(f"the history was not checked: {history.get('error')}")
        elif not history["ok"]:
            bad = ", ".join(f"{n} {k}" for k, n in history["counts"].items() if n)
            problems.append(f"the robots' shares break the history: {bad}")
    gap, bound = m.get("longest_write_gap_s"), m.get("write_gap_bound_s")
    if expect.gap_within_skip and (gap is None or bound is None or gap > bound):
        problems.append(
            f"{gap} s between two rounds written on the robots (bound: skip time "
            f"{SKIP_AFTER_S:g} s + one round = {bound} s)"
        )
    if expect.incomplete and (m["verdict"] != "INCOMPLETE" or m["exit_status"] == 0):
        problems.append(
            f"verdict {m['verdict']} and exit status {m['exit_status']} after a "
            "robot host was cut (INCOMPLETE and non-zero expected)"
        )
    return problems


def named_in_summary(summary: str) -> dict[str, list[str]]:
    """The robots summary.md names as missing rounds (``- MISSED rounds: rI ...``) and as
    ``LOST`` (``- LOST robot rI: ...``)."""
    return {
        "missed": sorted(set(re.findall(r"^- MISSED rounds: (\S+)", summary, re.M))),
        "lost": sorted(set(re.findall(r"^- LOST robot (\S+?):", summary, re.M))),
    }


def write_gaps(shares: dict[str, list[dict[str, str]]]) -> tuple[float | None, float | None]:
    """The longest gap (s) between consecutive rounds as the robots wrote them (a round's
    time: its last write on any robot, rows with a round number only), and the median gap."""
    last: dict[int, float] = {}
    for rows in shares.values():
        for r in rows:
            try:
                n, t = int(r["round"]), float(r["wall_time"])
            except (KeyError, TypeError, ValueError):
                continue
            last[n] = max(t, last.get(n, t))
    times = sorted(last.values())
    gaps = [b - a for a, b in zip(times, times[1:])]
    if not gaps:
        return None, None
    return round(max(gaps), 2), round(statistics.median(gaps), 2)


def judge_history(folder: Path, robots: list[str]) -> dict[str, Any]:
    """The history checker's verdict on the ``shares_<robot>.csv`` files in ``folder``:
    ``ok``, ``counts`` by kind, the first violations; ``ok`` None with ``error`` when it
    could not read a file."""
    try:
        verdict = check_history(folder, robots)
    except HistoryInputError as exc:  # a malformed file is a finding, not a crash
        return {"ok": None, "error": f"{type(exc).__name__}: {exc}"}
    counts: dict[str, int] = {}
    for v in verdict.violations:
        kind = getattr(v.kind, "value", str(v.kind))
        counts[kind] = counts.get(kind, 0) + 1
    return {
        "ok": bool(verdict.ok),
        "counts": counts,
        "first": [v.to_json() for v in verdict.violations[:3]],
    }


def gather_shares(fed: Federation, folder: Path) -> dict[str, list[dict[str, str]]]:
    """Copy each robot's ``shares_<robot>.csv`` from its own host's disk into ``folder``;
    their rows (a robot whose host wrote none: no rows)."""
    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for rid in fed.robots:
        src = fed.shares_file(rid)
        text = src.read_text(encoding="utf-8", errors="replace") if src and src.is_file() else ""
        (folder / f"shares_{rid}.csv").write_text(text, encoding="utf-8")
        out[rid] = list(csv.DictReader(io.StringIO(text))) if text else []
    return out


def run_case(
    case: Case,
    hosts: int,
    work: Path,
    delay_ms: float = 0.0,
    rounds: int | None = None,
    itinerary: str = "chain",
) -> dict[str, Any]:
    """One run of ``case`` on ``hosts`` robot hosts, its files under ``work`` (each host's on
    a disk of its own, copied out to ``work/<host>`` at the end), every link into a robot host
    ``delay_ms`` slow each way, ``rounds`` rounds (None: the case's plan) over an
    ``itinerary``; its figures, ``problems`` and ``passed`` (a run the benchmark could not
    carry out fails with ``error``)."""
    plan = dataclasses.replace(case.plan(hosts), delay_ms=delay_ms, itinerary=itinerary)
    if rounds is not None:
        plan = dataclasses.replace(
            plan, iterations=plan.respite * rounds, timeout_s=60.0 + 3 * 2.5 * rounds
        )
    names = [f"h{i}" for i in range(1, hosts + 1)] + ["driver"]
    started = time.monotonic()
    record: dict[str, Any] = {"fault": case.name, "itinerary": itinerary}
    work.mkdir(parents=True, exist_ok=True)
    with Lab(names, private=work.resolve()) as lab:
        fed = Federation(lab, work.resolve(), plan, name=f"faults-{case.name.replace('_', '-')}")
        try:
            fed.start_robot_hosts()
            fed.start_driver()
            acted: Acted = case.act(fed)
        except (FaultBenchError, OSError, ValueError, subprocess.TimeoutExpired) as exc:
            fed.copy_out()
            record.update(
                actions=fed.actions,
                error=f"{type(exc).__name__}: {exc}",
                problems=[f"the benchmark could not carry the run out: {exc}"],
                passed=False,
                wall_s=round(time.monotonic() - started, 1),
            )
            return record
        # the robots may still be writing (a run whose driver was cut or killed): bounded
        wait_robots_idle(fed, 30.0)
        shares = gather_shares(fed, work / "history")
        foreign = fed.foreign_files()
        copy_problems = fed.copy_out()
    summary_path = acted.results / "summary.md"
    summary = summary_path.read_text(encoding="utf-8") if summary_path.is_file() else ""
    rows = read_rows(acted.results)
    m = measure(
        rows or [],
        summary,
        acted.exit_status,
        acted.t_fault,
        fed.t0,
        fed.robots,
        plan.rounds,
        acted.victim,
    )
    m["history"] = judge_history(work / "history", fed.robots)
    m["longest_write_gap_s"], write_median = write_gaps(shares)
    m["write_gap_bound_s"] = (
        round(SKIP_AFTER_S + write_median, 2) if write_median is not None else None
    )
    named = named_in_summary(summary)
    m["summary_missed"], m["summary_lost"] = named["missed"], named["lost"]
    m["any_lost"] = bool(named["lost"])
    m["no_shared_disk"] = True
    # files a host wrote under a path of another host's (its copy: work/<host>/_foreign/)
    m["foreign_files"] = foreign
    m["round_log_lines_not_written"] = lines_not_written(work, fed.robots, fed.host_of)
    if "collect_exit" in acted.extra:
        m["collect_rounds_found"] = m["rounds_done"]
    problems = judge(m, slowed(case.expect, delay_ms, m["normal_gap_s"]))
    if rows is None:
        problems.insert(0, "no rounds.csv was written")
    if copy_problems:
        acted.notes.append("could not copy out: " + "; ".join(copy_problems))
    record.update(
        actions=fed.actions,
        notes=acted.notes,
        **acted.extra,
        **m,
        delay_ms=delay_ms,
        problems=problems,
        passed=not problems,
        wall_s=round(time.monotonic() - started, 1),
    )
    if not problems:
        return record
    record["driver_stderr_tail"] = fed.driver_tail(600)
    return record


#: the warning of a robot host's node that could neither post a round log line to the
#: driver's console nor append it to the log's path on its own disk (dfrl_round_log.pl)
NOT_WRITTEN = "round log line not written"


def lines_not_written(
    work: Path, robots: list[str], host_of: Callable[[str], str]
) -> dict[str, int]:
    """Per robot host (its ``robot.log``, copied out to ``work/<host>``), the round log lines
    its node could not write anywhere: lost from the run's round log (only hosts with some)."""
    out = {}
    for rid in robots:
        log = work / host_of(rid) / "robot.log"
        text = log.read_text(encoding="utf-8", errors="replace") if log.is_file() else ""
        if text.count(NOT_WRITTEN):
            out[host_of(rid)] = text.count(NOT_WRITTEN)
    return out


def wait_robots_idle(fed: Federation, timeout_s: float) -> None:
    """Wait (at most ``timeout_s``) until no robot's shares file has grown for 3 s."""
    deadline = time.monotonic() + timeout_s
    seen = {r: fed.shares(r) for r in fed.robots}
    still = time.monotonic()
    while time.monotonic() < deadline and time.monotonic() - still < 3.0:
        time.sleep(0.5)
        now = {r: fed.shares(r) for r in fed.robots}
        if now != seen:
            seen, still = now, time.monotonic()


def slowed(expect: Expectation, delay_ms: float, normal_gap_s: float | None) -> Expectation:
    """``expect`` on slow links: its time bounds grow by the run's normal gap between rounds
    (a round at that link's pace); unchanged without a delay."""
    if delay_ms <= 0 or not normal_gap_s:
        return expect
    return dataclasses.replace(
        expect,
        recovery_bound_s=expect.recovery_bound_s + normal_gap_s,
        stall_bound_s=expect.stall_bound_s + normal_gap_s,
    )


def _median(values: list[Any]) -> float | None:
    xs = [v for v in values if v is not None]
    return round(statistics.median(xs), 2) if xs else None


def summarize(case: Case, runs: list[dict[str, Any]], itinerary: str = "chain") -> dict[str, Any]:
    """The JSON object of one fault: its runs, their medians and the verdict."""
    return {
        "fault": case.name,
        "itinerary": itinerary,
        "what": case.what,
        "expectation": case.expect.text(),
        "runs": len(runs),
        "passed_runs": sum(r["passed"] for r in runs),
        "passed": all(r["passed"] for r in runs),
        "median": {
            k: _median([r.get(k) for r in runs])
            for k in (
                "recovery_s",
                "longest_stall_s",
                "normal_gap_s",
                "rounds_done",
                "rounds_unverified",
                "longest_write_gap_s",
                "wall_s",
            )
        },
        "history_clean_runs": sum(bool((r.get("history") or {}).get("ok")) for r in runs),
        "rounds_planned": runs[0].get("rounds_planned") if runs else None,
        "tables_identical_runs": sum(bool(r.get("tables_identical")) for r in runs),
        "truthful_runs": sum(bool(r.get("truthful")) for r in runs),
        "per_run": runs,
    }


def run(
    faults: list[str],
    runs: int = 3,
    hosts: int = 4,
    keep: Path | None = None,
    on_fault: Callable[[dict[str, Any]], None] | None = None,
    cases: dict[str, Case] | None = None,
    delay_ms: float = 0.0,
    rounds: int | None = None,
    itineraries: tuple[str, ...] = ("chain",),
) -> list[dict[str, Any]]:
    """Run each fault of ``faults`` ``runs`` times on ``hosts`` robot hosts, every link into
    a robot host ``delay_ms`` slow each way, for each itinerary of ``itineraries``, ``rounds``
    rounds (None: each case's own plan); one summary per fault and itinerary (see
    :func:`summarize`), handed to ``on_fault`` as soon as it is done. Files go to ``keep``
    (else a temporary folder, removed)."""
    cases = CASES if cases is None else cases
    unknown = [f for f in faults if f not in cases]
    if unknown:
        raise ValueError(f"unknown fault(s) {', '.join(unknown)}; known: {', '.join(cases)}")
    if not 2 <= hosts <= 5:
        raise ValueError(f"--hosts must be 2 to 5 (one arena each), got {hosts}")
    if runs < 1:
        raise ValueError(f"--runs must be at least 1, got {runs}")
    if not 0 <= delay_ms <= 2000:
        raise ValueError(f"--delay-ms must be 0 to 2000, got {delay_ms:g}")
    if rounds is not None and not 5 <= rounds <= 200:
        raise ValueError(f"--rounds must be 5 to 200, got {rounds}")
    bad = [i for i in itineraries if i not in ITINERARIES]
    if bad or not itineraries:
        raise ValueError(
            f"--itinerary must be among {', '.join(ITINERARIES)}, got "
            f"{' '.join(itineraries) or 'none'}"
        )
    base = keep if keep is not None else Path(tempfile.mkdtemp(prefix="dfrl-faults-"))
    out = []
    try:
        for itinerary in itineraries:
            for name in faults:
                tag = name if itinerary == "chain" else f"{name}-{itinerary}"
                results = [
                    run_case(cases[name], hosts, base / f"{tag}-{i}", delay_ms, rounds, itinerary)
                    for i in range(1, runs + 1)
                ]
                for i, r in enumerate(results, 1):
                    r["run"] = i
                out.append(summarize(cases[name], results, itinerary))
                if on_fault is not None:
                    on_fault(out[-1])
    finally:
        if keep is None:
            shutil.rmtree(base, ignore_errors=True)
    return out
