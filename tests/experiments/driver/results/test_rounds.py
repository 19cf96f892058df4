"""Shares, their matching to rounds, and ``rounds.csv`` (hand-made rows, no processes)."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.agent_log import AgentLog, RoundRecord, Skip
from dfrl.experiments.driver.results.rounds import (Share, count_equal, count_unverified,
                                                    match_shares, read_rounds_csv, read_shares,
                                                    write_rounds_csv)


def test_match_shares_picks_the_share_inside_the_round() -> None:
    rec = RoundRecord("fed", 2, 10.0, 11.0, 2, 0, "average", ("r1", "r2"))
    shares = {
        "r1": [Share("r1", 1, 50, 9.99, "a"), Share("r1", 2, 100, 10.9, "b"),
               Share("r1", 3, 150, 11.2, "c")],
        "r2": [Share("r2", 1, 50, 9.5, "a")],
    }
    got = match_shares(rec, shares)
    assert got["r1"].digest == "b"
    assert got["r2"] is None


def test_write_rounds_csv_all_equal(tmp_path: Path) -> None:
    log = AgentLog("fed", [RoundRecord("fed", 1, 1.0, 2.0, 2, 10, "average", ("r1", "r2")),
                           RoundRecord("fed", 2, 3.0, 4.0, 2, 10, "average", ("r1", "r2"))])
    shares = {"r1": [Share("r1", 1, 5, 1.5, "x"), Share("r1", 2, 10, 3.5, "y")],
              "r2": [Share("r2", 1, 5, 1.4, "x"), Share("r2", 2, 10, 3.4, "z")]}
    rows = write_rounds_csv(tmp_path / "rounds.csv", [log], ["r1", "r2", "r3"], shares)
    assert [r["all_equal"] for r in rows] == [True, False]
    with open(tmp_path / "rounds.csv", newline="") as fh:
        written = list(csv.DictReader(fh))
    assert written[0]["digest_r1"] == written[0]["digest_r2"] == "x"
    assert written[0]["digest_r3"] == ""
    assert written[1]["all_equal"] == "false"


def test_read_rounds_csv_counts_equal_rounds_from_the_data(tmp_path: Path) -> None:
    log = AgentLog("fed", [RoundRecord("fed", 1, 1.0, 2.0, 1, 10, "average", ("r1",)),
                           RoundRecord("fed", 2, 3.0, 4.0, 1, 10, "average", ("r1",))])
    shares = {"r1": [Share("r1", 1, 5, 1.5, "x")]}
    write_rounds_csv(tmp_path / "rounds.csv", [log], ["r1"], shares)
    rows = read_rounds_csv(tmp_path / "rounds.csv")
    assert [r["all_equal"] for r in rows] == [True, False]
    assert count_equal(rows) == 1
    bad = tmp_path / "bad.csv"
    bad.write_text("agent,round,all_equal\nfed,1,yes\n", encoding="utf-8")
    with pytest.raises(ValueError):
        read_rounds_csv(bad)


def test_shares_with_a_round_are_matched_by_agent_and_round_not_by_clock() -> None:
    # the robot's clock is 100 s ahead of the agent's: times say nothing, round numbers do
    rec = RoundRecord("fed", 2, 10.0, 11.0, 2, 0, "average", ("r1", "r2"))
    shares = {
        "r1": [Share("r1", 1, 50, 110.2, "a", round=1, agent="fed", epoch=0),
               Share("r1", 2, 100, 110.9, "b", round=2, agent="fed", epoch=0),
               Share("r1", 3, 100, 111.0, "b2", round=2, agent="other", epoch=0)],
        # a resurrected agent (epoch 1) wrote round 2 again: its share counts
        "r2": [Share("r2", 2, 100, 10.5, "old", round=2, agent="fed", epoch=0),
               Share("r2", 3, 100, 99.0, "new", round=2, agent="fed", epoch=1)],
    }
    got = match_shares(rec, shares)
    assert got["r1"].digest == "b"
    assert got["r2"].digest == "new"


def test_a_share_with_a_round_beats_a_share_inside_the_time_window() -> None:
    rec = RoundRecord("fed", 3, 10.0, 11.0, 1, 0, "average", ("r1",))
    shares = {"r1": [Share("r1", 1, 50, 10.5, "clock"),
                     Share("r1", 2, 100, 50.0, "numbered", round=3, agent="fed")]}
    assert match_shares(rec, shares)["r1"].digest == "numbered"
    # a numbered share of another round is not taken even inside the window
    shares = {"r1": [Share("r1", 1, 50, 10.5, "r2", round=2, agent="fed")]}
    assert match_shares(rec, shares)["r1"] is None


def test_read_shares_reads_the_k4_columns_and_old_files(tmp_path: Path) -> None:
    new = tmp_path / "shares_r1.csv"
    new.write_text("robot,share_index,iteration,wall_time,digest,round,agent,epoch\n"
                   "r1,1,50,1.5,aa,1,fed,0\nr1,2,100,2.5,bb,,,\nr1,3,15", encoding="utf-8")
    rows = read_shares(new)
    assert [(s.digest, s.round, s.agent, s.epoch) for s in rows] == \
        [("aa", 1, "fed", 0), ("bb", None, None, None)]
    old = tmp_path / "shares_r2.csv"
    old.write_text("robot,share_index,iteration,wall_time,digest\nr2,1,50,1.5,cc\n",
                   encoding="utf-8")
    assert read_shares(old) == [Share("r2", 1, 50, 1.5, "cc")]


def test_rounds_csv_says_which_stops_were_skipped_and_why(tmp_path: Path) -> None:
    rec = RoundRecord("fed", 1, 1.0, 2.0, 2, 10, "average", ("r1", "r3"),
                      (Skip("r2", "connection refused\n(after 2 retries)"),), retries=2)
    shares = {"r1": [Share("r1", 1, 5, 1.5, "x", 1, "fed", 0)],
              "r3": [Share("r3", 1, 5, 1.5, "x", 1, "fed", 0)]}
    rows = write_rounds_csv(tmp_path / "rounds.csv", [AgentLog("fed", [rec])],
                            ["r1", "r2", "r3"], shares)
    assert rows[0]["all_equal"] is True
    written = read_rounds_csv(tmp_path / "rounds.csv")[0]
    assert written["skipped"] == "r2: connection refused (after 2 retries)"
    assert written["retries"] == "2" and written["digest_r2"] == ""


def test_rounds_whose_missing_record_hides_nothing_are_unverified_not_differing() -> None:
    rows = [
        {"all_equal": True, "digest_r1": "a", "digest_r2": "a", "digest_r3": "a"},
        # r3's record lost with its host; the others agree: not verifiable, not a difference
        {"all_equal": False, "digest_r1": "b", "digest_r2": "b", "digest_r3": "missing"},
        # control: the records there disagree: a difference, whatever is missing
        {"all_equal": False, "digest_r1": "c", "digest_r2": "d", "digest_r3": "missing"},
        # control: nothing missing, tables differ
        {"all_equal": False, "digest_r1": "e", "digest_r2": "f", "digest_r3": ""},
    ]
    assert count_equal(rows) == 1
    assert count_unverified(rows) == 1


def test_the_shares_win_over_a_log_that_skipped_a_robot_they_show_written(tmp_path: Path) -> None:
    # Prepare: the log skipped r1 in round 2, but r1 recorded a write of round 2 (the other
    # copy wrote it); r2, the robot that was cut off, recorded none
    recs = [RoundRecord("fed", 1, 1.0, 2.0, 3, 10, "average", ("r1", "r2", "r3")),
            RoundRecord("fed", 2, 3.0, 4.0, 2, 10, "average", ("r3",),
                        (Skip("r1", "no answer"), Skip("r2", "no answer")))]
    shares = {"r1": [Share("r1", 1, 5, 1.5, "x", 1, "fed", 1),
                     Share("r1", 2, 10, 3.5, "y", 2, "fed", 1)],
              "r2": [Share("r2", 1, 5, 1.5, "x", 1, "fed", 1)],
              "r3": [Share("r3", 1, 5, 1.5, "x", 1, "fed", 1),
                     Share("r3", 2, 10, 3.5, "y", 2, "fed", 1)]}
    # Execute
    rows = write_rounds_csv(tmp_path / "rounds.csv", [AgentLog("fed", recs)],
                            ["r1", "r2", "r3"], shares)
    # Assert: r1 is counted written, not skipped, and the row says why; r2 stays skipped
    row = read_rounds_csv(tmp_path / "rounds.csv")[1]
    assert row["skipped"] == "r2: no answer" and row["written"] == "r1 r3"
    assert row["note"] == "r1 logged skipped but recorded a write of this round: counted written"
    assert row["digest_r1"] == row["digest_r3"] == "y" and row["digest_r2"] == ""
    assert rows[1]["all_equal"] is True and row["reconstructed"] is False


def test_a_round_only_in_the_shares_is_rebuilt_and_marked(tmp_path: Path) -> None:
    log = AgentLog("fed", [RoundRecord("fed", 1, 1.0, 2.0, 2, 10, "average", ("r1", "r2"))])
    shares = {"r1": [Share("r1", 1, 5, 1.5, "x", 1, "fed", 0),
                     Share("r1", 2, 10, 7.25, "y", 2, "fed", 1)],
              "r2": [Share("r2", 1, 5, 1.5, "x", 1, "fed", 0),
                     Share("r2", 2, 10, 7.5, "y", 2, "fed", 1)],
              "r3": [Share("r3", 1, 5, 9.0, "z", 1, "other", 0)]}
    write_rounds_csv(tmp_path / "rounds.csv", [log], ["r1", "r2", "r3"], shares)
    rows = read_rounds_csv(tmp_path / "rounds.csv")
    assert [(r["agent"], r["round"], r["reconstructed"]) for r in rows] == \
        [("fed", "1", False), ("fed", "2", True), ("other", "1", True)]
    rebuilt = rows[1]
    assert rebuilt["written"] == rebuilt["visited"] == "r1 r2" and rebuilt["epoch"] == "1"
    assert (rebuilt["start"], rebuilt["end"]) == ("7.25", "7.5")
    assert rebuilt["duration_ms"] == rebuilt["hops"] == rebuilt["method"] == ""
    assert rebuilt["all_equal"] and rebuilt["digest_r1"] == "y" and "rebuilt" in rebuilt["note"]
    assert rows[2]["written"] == "r3" and rows[2]["digest_r3"] == "z"
