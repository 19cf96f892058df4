"""The agent's JSON-lines round log (contract C2), read back by hand-written lines."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.agent_log import (Aborted, ControlEvent, RoundRecord, Skip, Superseded,
                                                kept_logs, parse_event, read_rounds_log)


def _write(path: Path, *lines: str) -> Path:
    path.write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    return path


def test_read_rounds_log(tmp_path: Path) -> None:
    # Prepare
    log = _write(
        tmp_path / "rounds.log",
        '{"event":"round","agent":"fed","round":1,"start":10.0,"end":10.5,"hops":2,'
        '"bytes":4860,"method":"average","visited":["r1","r2"],"skipped":[]}',
        '{"event":"control","agent":"fed","round":2,"command":"method(median)",'
        '"status":"applied"}',
        '{"event":"round","agent":"fed","round":2,"start":11.0,"end":11.5,"hops":2,'
        '"bytes":4860,"method":"median","visited":["r1"],'
        '"skipped":[{"robot":"r2","reason":"connection refused"}]}',
        "round(3, 1.0, 2.0, 2, 0, average, [r1]).",
        '{"event":"finished","agent":"fed","round":2}')
    # Execute
    got = read_rounds_log(log, "fed")
    # Assert
    assert [r.round for r in got.rounds] == [1, 2]
    assert got.rounds[1] == RoundRecord("fed", 2, 11.0, 11.5, 2, 4860, "median", ("r1",),
                                        (Skip("r2", "connection refused"),))
    assert got.rounds[0].duration_ms == pytest.approx(500.0)
    assert got.controls == [ControlEvent(2, "method(median)", "applied")]
    assert got.finished == 2
    assert got.unreadable == ["round(3, 1.0, 2.0, 2, 0, average, [r1])."]
    assert read_rounds_log(tmp_path / "missing.log", "fed").rounds == []


def test_aborted_ignored_control_and_bad_lines_are_kept(tmp_path: Path) -> None:
    log = _write(
        tmp_path / "rounds.log",
        '{"event":"aborted","agent":"fed","round":4,"error":"timeout"}',
        '{"event":"control","agent":"fed","round":4,"command":"method(nope)",'
        '"status":"ignored","reason":"unknown method"}',
        '{"event":"round","agent":"fed","round":5}',                       # fields missing
        '{"event":"finished","agent":"other","round":3}',                  # not this agent
        '{"event":"teleport","agent":"fed"}',                              # unknown event
        '[1, 2]',
        '{"event":"round","agent":"fed","round":6,"start":1.0,"en')        # torn last line
    got = read_rounds_log(log, "fed")
    assert got.aborted == [Aborted(4, "timeout")]
    assert got.controls == [ControlEvent(4, "method(nope)", "ignored", "unknown method")]
    assert got.rounds == [] and got.finished is None
    assert len(got.unreadable) == 5


def test_parse_event_round_trips_what_json_writes() -> None:
    event = {"event": "round", "agent": "fed_q", "round": 3, "start": 1764600000.12,
             "end": 1764600000.25, "hops": 8, "bytes": 4860, "method": "my method",
             "visited": ["r1", "r2", "r3"], "skipped": []}
    assert parse_event(json.dumps(event)) == event
    with pytest.raises(ValueError):
        parse_event('"just a string"')
    with pytest.raises(ValueError):
        parse_event('{"no_event": 1}')


def test_a_round_logged_by_a_late_copy_and_its_replacement_counts_once(tmp_path: Path) -> None:
    r = ('{"event":"round","agent":"fed","round":%d,"start":1.0,"end":2.0,"hops":2,'
         '"bytes":0,"method":"average","visited":["r1"],"skipped":[],"epoch":%d}')
    log = _write(tmp_path / "rounds.log", r % (1, 1), r % (2, 1),
                 '{"event":"resurrected","agent":"fed","round":2,"epoch":2,"from":"a:1",'
                 '"dead":"b:2"}',
                 r % (2, 2), '{"event":"superseded","agent":"fed","round":3,"epoch":1,"by":2}',
                 r % (3, 2))
    got = read_rounds_log(log, "fed")
    assert [(x.round, x.epoch) for x in got.rounds] == [(1, 1), (2, 2), (3, 2)]
    assert [(x.round, x.epoch) for x in got.duplicates] == [(2, 1)]
    assert got.superseded == [Superseded(3, 1, 2)] and len(got.resurrections) == 1
    assert got.unreadable == []


def _round_line(n: int, start: float) -> str:
    return (f'{{"event":"round","agent":"fed","round":{n},"start":{start},"end":{start + 0.5},'
            '"hops":2,"bytes":10,"method":"average","visited":["r1","r2"],"skipped":[]}')


def test_kept_logs_merged_each_line_once(tmp_path: Path) -> None:
    # Prepare: the console got rounds 2 (twice: a post sent again), 1 (late, out of order);
    # robot r1 kept 1..3 and the finished line, robot r2 kept round 3 (logged there after a
    # resurrection, epoch 2); another agent's kept log and a non-log file beside them
    console = _write(tmp_path / "rounds_fed.log", _round_line(2, 20.0), _round_line(2, 20.0),
                     _round_line(1, 10.0))
    (tmp_path / "agent_logs" / "r1").mkdir(parents=True)
    (tmp_path / "agent_logs" / "r2").mkdir()
    _write(tmp_path / "agent_logs" / "r1" / "rounds_fed.log", _round_line(1, 10.0),
           _round_line(2, 20.0), _round_line(3, 30.0),
           '{"event":"finished","agent":"fed","round":3}')
    r3 = _round_line(3, 31.0).replace('"skipped":[]', '"skipped":[],"epoch":2')
    _write(tmp_path / "agent_logs" / "r2" / "rounds_fed.log", r3)
    _write(tmp_path / "agent_logs" / "r2" / "rounds_other.log", _round_line(9, 90.0))
    # Execute
    kept = kept_logs(tmp_path, "fed")
    alone = read_rounds_log(console, "fed")
    merged = read_rounds_log(console, "fed", kept=kept)
    # Assert: the console's file alone: rounds 1, 2 in order, the repeated line read once;
    # merged: every round once, round 3 from the higher epoch and the other one a duplicate
    assert kept == [tmp_path / "agent_logs" / "r1" / "rounds_fed.log",
                    tmp_path / "agent_logs" / "r2" / "rounds_fed.log"]
    assert [r.round for r in alone.rounds] == [1, 2] and alone.duplicates == []
    assert [(r.round, r.start, r.epoch) for r in merged.rounds] == \
        [(1, 10.0, 0), (2, 20.0, 0), (3, 31.0, 2)]
    assert [(r.round, r.start) for r in merged.duplicates] == [(3, 30.0)]
    assert merged.finished == 3 and merged.unreadable == []
