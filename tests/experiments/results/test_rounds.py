"""Shares, their matching to rounds, and ``rounds.csv`` (hand-made rows, no processes)."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

from dfrl.experiments.results.agent_log import AgentLog, RoundRecord
from dfrl.experiments.results.rounds import (Share, count_equal, match_shares, read_rounds_csv,
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
