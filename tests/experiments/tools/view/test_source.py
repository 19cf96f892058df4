"""EventSource on results folders written by hand: incremental reads, order, inference."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from dfrl.experiments.tools.view import EventSource, append_event
from dfrl.experiments.tools.view.tail import CsvTail, FileTail

from .helpers import append, canonical, hop_order, round_line, write_run


def test_file_tail_reads_bounded_whole_lines_and_restarts(tmp_path: Path) -> None:
    p = tmp_path / "f.log"
    tail = FileTail(p, max_bytes=8)
    assert tail.read_lines() == []  # missing file
    p.write_text("abc\ndefghij\nkl")
    assert tail.read_lines() == ["abc"]  # 8 bytes: one whole line
    assert tail.read_lines() == ["defghij"]
    assert tail.read_lines() == [] and tail.offset == len(p.read_bytes())  # torn line waits
    append(p, "m\n")
    assert tail.read_lines() == ["klm"]
    p.write_text("new\n")  # a new run replaced the file
    assert tail.read_lines() == ["new"] and tail.restarted


def test_csv_tail_rows(tmp_path: Path) -> None:
    p = tmp_path / "m.csv"
    p.write_text("a,b\n1,2\n")
    tail = CsvTail(p)
    assert tail.read_rows() == [{"a": "1", "b": "2"}]
    append(p, "3,4\n5,")
    assert tail.read_rows() == [{"a": "3", "b": "4"}]


def test_rounds_hops_skips_and_method_switch_in_order(tmp_path: Path) -> None:
    write_run(tmp_path, ("r1", "r2", "r3"), iterations=150)
    src = EventSource(tmp_path)
    first = src.poll()
    kinds = [e["kind"] for e in first]
    assert kinds[0] == "run" and kinds.count("robot") == 3 and kinds.count("arena") == 3
    assert "agent" in kinds
    log = tmp_path / "rounds_fed_qlearning.log"
    # round 1: a share of r3 (the last stop) first: the forward pass is implied before it
    append(tmp_path / "shares_r3.csv", "r3,1,50,100.05,d,1,fed_qlearning,1\n")
    got = src.poll()
    assert hop_order(got, "fed_qlearning", 1) == [
        ("forward", "r1"),
        ("forward", "r2"),
        ("forward", "r3"),
        ("backward", "r3"),
    ]
    append(log, round_line(1, ["r1", "r2", "r3"], 100.0))
    append(log, round_line(2, ["r1", "r3"], 101.0, skipped=("r2",)))
    append(log, round_line(3, ["r1", "r3"], 102.0, method="max", skipped=("r2",)))
    append(log, '{"event":"finished","agent":"fed_qlearning","round":3}\n')
    src.poll()
    ev = src.events
    assert [e["seq"] for e in ev] == list(range(len(ev)))
    rounds = [e for e in ev if e["kind"] == "round"]
    assert [r["round"] for r in rounds] == [1, 2, 3]
    for r in rounds:
        assert hop_order(ev, "fed_qlearning", r["round"]) == canonical(r["visited"])
        last_hop = max(e["seq"] for e in ev if e["kind"] == "hop" and e["round"] == r["round"])
        assert last_hop < r["seq"]  # a round's hops come before it
    assert [(e["round"], e["robot"]) for e in ev if e["kind"] == "skip"] == [(2, "r2"), (3, "r2")]
    switch = [e for e in ev if e["kind"] == "method"]
    assert [(e["round"], e["previous"], e["method"]) for e in switch] == [(3, "average", "max")]
    assert ev[-1]["kind"] == "robot_state" or any(e["kind"] == "finished" for e in ev)
    # a remote robot skipped twice whose metrics never grew: inferred dead, not live-checked
    states = {e["robot"]: e["state"] for e in ev if e["kind"] == "robot_state"}
    assert states["r2"] in ("skipped", "dead")


def test_metrics_are_decimated_and_timed_by_shares(tmp_path: Path) -> None:
    write_run(tmp_path, ("r1",), iterations=2000, respite=1000)
    rows = "".join(f"r1,{i},{i * 0.5},{i * 0.1},0\n" for i in range(1, 2001))
    append(tmp_path / "metrics_r1.csv", rows)
    t = time.time() + 10.0  # after the run's start (nodes.json)
    append(
        tmp_path / "shares_r1.csv",
        f"r1,1,1000,{t},d,1,fed_qlearning,1\nr1,2,2000,{t + 100},d,2,fed_qlearning,1\n",
    )
    src = EventSource(tmp_path)
    ev = src.drain()
    pts = [p for e in ev if e["kind"] == "metrics" for p in e["points"]]
    assert pts[0][0] == 4 and pts[-1] == [2000, 1000.0, 200.0, 0.0]  # stride 2000 // 500
    assert len(pts) == 500 and all(b[0] > a[0] for a, b in zip(pts, pts[1:]))
    times = [e["t"] for e in ev if e["kind"] == "metrics"]
    assert times == sorted(times) and times[-1] == t + 100


def test_events_file_hops_states_poses_and_bad_lines(tmp_path: Path) -> None:
    write_run(tmp_path, ("r1", "r2"))
    src = EventSource(tmp_path)
    src.poll()
    for robot, phase in [("r1", "forward"), ("r2", "forward"), ("r2", "backward")]:
        append_event(
            tmp_path,
            {"kind": "hop", "agent": "fed_qlearning", "robot": robot, "phase": phase, "round": 1},
        )
    append_event(tmp_path, {"kind": "pose", "robot": "r1", "x": 0.1, "y": -0.2, "yaw": 1.0})
    append_event(
        tmp_path, {"kind": "robot_state", "robot": "r2", "state": "dead", "reason": "exit code -9"}
    )
    append(tmp_path / "events.jsonl", "not json\n")
    got = src.poll()
    assert [(e["phase"], e["robot"], e["inferred"]) for e in got if e["kind"] == "hop"] == [
        ("forward", "r1", False),
        ("forward", "r2", False),
        ("backward", "r2", False),
    ]
    assert any(e["kind"] == "pose" and e["x"] == 0.1 for e in got)
    dead = [e for e in got if e["kind"] == "robot_state"]
    assert dead and dead[0]["state"] == "dead" and dead[0]["inferred"] is False
    assert any(e["kind"] == "error" and "unreadable" in e["text"] for e in got)
    line = json.loads((tmp_path / "events.jsonl").read_text().splitlines()[0])
    assert isinstance(line["t"], float)


def test_append_event_needs_a_kind(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        append_event(tmp_path, {"robot": "r1"})
    with pytest.raises(ValueError):
        append_event(tmp_path, {"kind": "x", "v": float("nan")})
