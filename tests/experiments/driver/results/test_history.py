"""The history checker on hand-made histories, written as real ``shares_<robot>.csv`` files by
the robots' own writer (CsvLog, share_row): histories that break a rule must fail, clean ones
must pass; and ``dfrl check-history``'s exit codes."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.driver.results.history import (HistoryInputError, ViolationKind,
                                                     check_history, check_shares,
                                                     read_history_file)
from dfrl.experiments.driver.results.rounds import Share
from dfrl.experiments.robot_host.files import SHARE_FIELDS, CsvLog, share_row

#: A write: (robot, round, epoch, table value) or (robot, None, None, value) for a manual one.
Write = tuple[str, "int | None", "int | None", float]


def table(value: float) -> np.ndarray:
    """The aggregate a round wrote (a 3 x 2 table of one value): same value, same digest."""
    return np.full((3, 2), value)


def write_history(out: Path, writes: list[Write], agent: str = "fed_q") -> None:
    """Write ``writes`` in order into ``OUT/shares_<robot>.csv`` as the robot processes do."""
    logs: dict[str, CsvLog] = {}
    counts: dict[str, int] = {}
    for robot, rnd, epoch, value in writes:
        if robot not in logs:
            logs[robot] = CsvLog(out / f"shares_{robot}.csv", SHARE_FIELDS)
        counts[robot] = counts.get(robot, 0) + 1
        origin = None if rnd is None else {"round": rnd, "agent": agent, "epoch": epoch}
        logs[robot].row(share_row(robot, counts[robot], 50 * counts[robot], table(value),
                                  origin))
    for log in logs.values():
        log.close()


def clean(robots: tuple[str, ...] = ("r1", "r2", "r3"), rounds: int = 4,
          epoch: int = 0) -> list[Write]:
    """A clean run: every robot written every round, one aggregate per round."""
    return [(r, n, epoch, float(n)) for n in range(1, rounds + 1) for r in robots]


def kinds(out: Path) -> list[ViolationKind]:
    return [v.kind for v in check_history(out).violations]


# --- histories that must pass -------------------------------------------------------------

def test_a_clean_run_passes(tmp_path: Path) -> None:
    write_history(tmp_path, clean() + [("r1", None, None, 9.0)])   # and one write by hand
    verdict = check_history(tmp_path)
    assert verdict.ok, verdict.text()
    assert (verdict.writes, verdict.ignored, verdict.rounds, verdict.robots) == (12, 1, 4, 3)
    assert verdict.agents == ("fed_q",)
    assert verdict.text().startswith("history ok: 12 write(s) of 1 agent(s) in 4 round(s)")
    assert verdict.to_json()["ok"] is True and verdict.to_json()["violations"] == []


def test_a_robot_missing_rounds_passes(tmp_path: Path) -> None:
    # r3 was skipped in rounds 2 and 3 (unreachable) and written again in round 4
    writes = [w for w in clean() if not (w[0] == "r3" and w[1] in (2, 3))]
    write_history(tmp_path, writes)
    assert check_history(tmp_path).ok


def test_a_resurrection_with_a_higher_epoch_passes(tmp_path: Path) -> None:
    # epoch 0 wrote rounds 1-2 and r3 of round 3, then was lost in round 3's backward pass;
    # epoch 1 finished round 3 (same aggregate) without the dead stop and went on
    writes = clean(rounds=2) + [("r3", 3, 0, 3.0), ("r1", 3, 1, 3.0)] \
        + [(r, n, 1, float(n)) for n in (4, 5) for r in ("r1", "r3")] \
        + [(r, n, 2, float(n)) for n in (6,) for r in ("r1", "r2", "r3")]
    write_history(tmp_path, writes)
    verdict = check_history(tmp_path)
    assert verdict.ok, verdict.text()


# --- histories that must fail ---------------------------------------------------------------

def test_a_doubled_write_fails(tmp_path: Path) -> None:
    # after a partition both copies wrote r2 in round 3 (different aggregates)
    write_history(tmp_path, clean() + [("r2", 3, 1, 30.0)])
    verdict = check_history(tmp_path)
    doubled = [v for v in verdict.violations if v.kind is ViolationKind.DOUBLED_WRITE]
    assert len(doubled) == 1
    assert (doubled[0].agent, doubled[0].robots, doubled[0].round) == ("fed_q", ("r2",), 3)
    assert "2 writes" in doubled[0].detail and "2 different tables" in doubled[0].detail
    assert not verdict.ok and "doubled_write" in verdict.text()


def test_the_same_table_written_twice_is_still_a_doubled_write(tmp_path: Path) -> None:
    write_history(tmp_path, clean() + [("r2", 4, 0, 4.0)])
    assert kinds(tmp_path) == [ViolationKind.DOUBLED_WRITE]
    assert "the same table" in check_history(tmp_path).violations[0].detail


def test_an_epoch_regression_fails(tmp_path: Path) -> None:
    # r1 applied epoch 1 in round 3, then a write of epoch 0 in round 4 (in its file order)
    writes = clean(rounds=2) + [(r, 3, 1, 3.0) for r in ("r1", "r2", "r3")] \
        + [("r1", 4, 0, 4.0)]
    write_history(tmp_path, writes)
    verdict = check_history(tmp_path)
    regressed = [v for v in verdict.violations if v.kind is ViolationKind.EPOCH_REGRESSED]
    assert [(v.robots, v.round) for v in regressed] == [(("r1",), 4)]
    assert "epoch 0" in regressed[0].detail and "after epoch 1" in regressed[0].detail


def test_a_stale_epoch_fails_without_any_robot_seeing_both(tmp_path: Path) -> None:
    # a partition: epoch 1 took over at round 3 on r1's side, the late epoch 0 kept writing
    # rounds 3 and 4 at r2 alone; no robot applied both epochs, no round is doubled
    writes = clean(robots=("r1", "r2"), rounds=2) + [("r1", 3, 1, 3.0), ("r2", 3, 0, 3.0),
                                                     ("r1", 4, 1, 4.0), ("r2", 4, 0, 4.5)]
    write_history(tmp_path, writes)
    verdict = check_history(tmp_path)
    stale = [v for v in verdict.violations if v.kind is ViolationKind.STALE_EPOCH]
    assert [(v.robots, v.round) for v in stale] == [(("r2",), 4)]
    assert "epoch 1 had written round 3 already (r1)" in stale[0].detail
    # round 4's two tables differ too; round 3's agree (epoch 0 may finish its round)
    split = [v.round for v in verdict.violations if v.kind is ViolationKind.SPLIT_ROUND]
    assert split == [4]
    assert not any(v.kind is ViolationKind.DOUBLED_WRITE for v in verdict.violations)


def test_a_split_round_fails(tmp_path: Path) -> None:
    writes = [w for w in clean() if w[:2] != ("r3", 2)] + [("r3", 2, 0, 2.5)]
    write_history(tmp_path, writes)
    verdict = check_history(tmp_path)
    assert [v.kind for v in verdict.violations] == [ViolationKind.SPLIT_ROUND]
    v = verdict.violations[0]
    assert (v.robots, v.round) == (("r1", "r2", "r3"), 2)
    assert "2 different tables" in v.detail and "r1, r2:" in v.detail


def test_agents_are_checked_apart() -> None:
    # two agents (one per algorithm) write round 1 of their own: no doubled write, no split
    shares = {"r1": [Share("r1", 1, 50, 1.0, "a", 1, "fed_q", 0),
                     Share("r1", 2, 50, 1.1, "b", 1, "fed_sarsa", 3)],
              "r2": [Share("r2", 1, 50, 1.0, "a", 1, "fed_q", 0),
                     Share("r2", 2, 50, 1.1, "b", 1, "fed_sarsa", 3)]}
    verdict = check_shares(shares)
    assert verdict.ok and verdict.rounds == 2 and verdict.agents == ("fed_q", "fed_sarsa")
    shares["r2"][1] = Share("r2", 2, 50, 1.1, "c", 1, "fed_sarsa", 3)
    assert [v.agent for v in check_shares(shares).violations] == ["fed_sarsa"]


# --- the files: strict reading ---------------------------------------------------------------

def test_a_torn_last_line_is_left_out_and_counted(tmp_path: Path) -> None:
    write_history(tmp_path, clean(robots=("r1",), rounds=2))
    path = tmp_path / "shares_r1.csv"
    with open(path, "a", encoding="utf-8") as fh:
        fh.write("r1,3,150,17")             # the robot died while writing the row
    rows, torn = read_history_file(path, "r1")
    assert len(rows) == 2 and torn == 1
    verdict = check_history(tmp_path)
    assert verdict.ok and verdict.torn == 1 and "1 torn last line(s)" in verdict.text()


@pytest.mark.parametrize("row, line, why", [
    ("r1,3,150,17.0,abc,3,fed_q\n", 4, f"7 cells, the header has {len(SHARE_FIELDS)}"),
    ("r1,3,150,17.0,abc,three,fed_q,0,1.5\n", 4, "round is 'three'"),
    ("r2,3,150,17.0,abc,3,fed_q,0,1.5\n", 4, "of robot 'r2'"),
    ("r1,3,150,17.0,,3,fed_q,0,1.5\n", 4, "no digest"),
])
def test_a_malformed_row_is_located(tmp_path: Path, row: str, line: int, why: str) -> None:
    write_history(tmp_path, clean(robots=("r1",), rounds=2))
    with open(tmp_path / "shares_r1.csv", "a", encoding="utf-8") as fh:
        fh.write(row)
        fh.write("r1,4,200,18.0,abcd,4,fed_q,0\n")
    with pytest.raises(HistoryInputError) as err:
        check_history(tmp_path)
    assert err.value.line == line and err.value.path == tmp_path / "shares_r1.csv"
    assert why in str(err.value) and f"shares_r1.csv:{line}:" in str(err.value)


def test_no_history_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(HistoryInputError, match="no shares_"):
        check_history(tmp_path)
    with pytest.raises(HistoryInputError, match="no such folder"):
        check_history(tmp_path / "nowhere")
    (tmp_path / "shares_r1.csv").write_text("a,b\n1,2\n", encoding="utf-8")
    with pytest.raises(HistoryInputError, match="no column robot"):
        check_history(tmp_path)
    # the robots named: a missing file is a robot that recorded nothing
    assert check_history(tmp_path, robots=["r9"]).writes == 0


# --- the command ---------------------------------------------------------------------------

def test_check_history_command_exit_codes(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    good, bad, empty = tmp_path / "good", tmp_path / "bad", tmp_path / "empty"
    for d in (good, bad, empty):
        d.mkdir()
    write_history(good, clean())
    write_history(bad, clean() + [("r2", 3, 1, 30.0)])
    assert main(["check-history", str(good)]) == 0
    assert capsys.readouterr().out.startswith("history ok")
    assert main(["check-history", str(bad), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["ok"] is False and report["counts"]["doubled_write"] == 1
    assert report["violations"][0]["robots"] == ["r2"]
    assert main(["check-history", str(empty)]) == 2
    assert "no shares_<robot>.csv" in capsys.readouterr().err
    # shares files without one agent write: nothing was checked, which is no "ok"
    (empty / "shares_r1.csv").write_text(
        "robot,share_index,iteration,wall_time,digest,round,agent,epoch\n")
    assert main(["check-history", str(empty)]) == 2
    assert "nothing to check" in capsys.readouterr().err


# --- a real run ----------------------------------------------------------------------------

def test_a_real_run_passes_and_a_doubled_write_added_to_it_fails(tmp_path: Path) -> None:
    from dfrl.experiments.driver.collect import collect
    from dfrl.experiments.driver.launcher import run
    from dfrl.experiments.processes import find_swipl

    from ..launcher.helpers import small_config

    if find_swipl() is None:
        pytest.skip("needs swipl")
    # Prepare: a short real run of 2 robots
    res = run(small_config(), tmp_path, progress=None)
    assert res.ok and res.history is not None and res.history.ok, res.history
    verdict = check_history(tmp_path)
    assert verdict.ok and (verdict.writes, verdict.rounds, verdict.robots) == (8, 4, 2)
    assert "## History: ok" in (tmp_path / "summary.md").read_text(encoding="utf-8")
    # Execute: r2 applies round 2 again (a late copy of a lower epoch, another table), as a
    # robot process appends it, and the end-of-run files are written again (dfrl collect)
    last = read_history_file(tmp_path / "shares_r2.csv", "r2")[0][-1]
    log = CsvLog(tmp_path / "shares_r2.csv", SHARE_FIELDS, keep=lambda row: True)
    log.row(share_row("r2", last.index + 1, last.iteration, table(7.0),
                      {"round": 2, "agent": last.agent, "epoch": 0}))
    log.close()
    again = collect(tmp_path, progress=None, wait_s=0.0)
    # Assert: the checker names the doubled write, the run is no longer complete
    found = {v.kind for v in check_history(tmp_path).violations}
    assert ViolationKind.DOUBLED_WRITE in found and ViolationKind.EPOCH_REGRESSED in found
    assert not again.ok and not again.complete
    summary = (tmp_path / "summary.md").read_text(encoding="utf-8")
    assert "## History: VIOLATED" in summary and "federation INCOMPLETE" in summary
    assert "HISTORY VIOLATED" in summary and "r2 applied 2 writes" in summary
    assert main(["check-history", str(tmp_path)]) == 1


def test_a_grid_federations_function_learners_are_left_out_of_split_round(
        tmp_path: Path) -> None:
    # r3 learns with dqn in a grid federation: after a share it holds its own Q-function at
    # the grid (distilled), not the aggregate; r1 and r2 hold the aggregate
    from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
    from dfrl.experiments.driver.results.files import write_json

    writes = [(r, n, 1, float(n) + (0.5 if r == "r3" else 0.0)) for n in (1, 2)
              for r in ("r1", "r2", "r3")]
    write_history(tmp_path, writes, agent="fed_grid")
    # control: without a config saying so, r3's tables are a split round
    assert kinds(tmp_path) == [ViolationKind.SPLIT_ROUND] * 2
    config = ExperimentConfig(robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4"),
                                      RobotSpec("r3", "r2", "dqn")), federation="grid")
    write_json(tmp_path / "config.json", config.public_dict())
    assert check_history(tmp_path).ok
    # r1's table differing still is one
    write_history(tmp_path, writes[:-3] + [("r1", 2, 1, 9.0), ("r2", 2, 1, 2.0),
                                           ("r3", 2, 1, 2.5)], agent="fed_grid")
    assert kinds(tmp_path) == [ViolationKind.SPLIT_ROUND]
