"""``metrics.csv``: merging the per-robot files and the shares into one row per robot and
iteration, and reading the curves back (also from files of the older format, which had a
second row at a robot's last iteration)."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.driver.results.metrics import (METRICS_FIELDS, MetricsFormatError,
                                                     merge_metrics, read_metrics)
from dfrl.experiments.robot_host.files import METRIC_FIELDS, SHARE_FIELDS

METRICS_HEADER = ",".join(METRIC_FIELDS) + "\n"
SHARES_HEADER = ",".join(SHARE_FIELDS) + "\n"


def _robot_metrics(folder: Path, robot: str, q: list[float]) -> None:
    """``metrics_<robot>.csv`` as a robot writes it (csv's CRLF line ends): iteration i has
    q_sum q[i-1], cumulative reward i, collisions i // 2."""
    rows = "".join(f"{robot},{i},{v!r},{float(i)!r},{i // 2}\r\n" for i, v in enumerate(q, 1))
    (folder / f"metrics_{robot}.csv").write_text(METRICS_HEADER.replace("\n", "\r\n") + rows,
                                                 encoding="utf-8", newline="")


def _shares(folder: Path, robot: str, writes: list[tuple[int, str]],
            header: str = SHARES_HEADER) -> None:
    """``shares_<robot>.csv``: one row per (iteration, q_sum text) (q_sum "" : not recorded;
    ``header`` without ``q_sum``: the older format, whose rows have no such cell)."""
    old = "q_sum" not in header
    rows = "".join(f"{robot},{k},{it},1.0,{'ab' * 32},{k},fed_qlearning,1"
                   + ("" if old else f",{q}") + "\n" for k, (it, q) in enumerate(writes, 1))
    (folder / f"shares_{robot}.csv").write_text(header + rows, encoding="utf-8")


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_merge_and_read_metrics(tmp_path: Path) -> None:
    for robot in ("r1", "r2"):
        (tmp_path / f"metrics_{robot}.csv").write_text(
            "robot,iteration,q_sum,cumulative_reward,collisions\n"
            f"{robot},1,0.5,1.0,0\n{robot},2,0.75,2.0,1\n{robot},3,0.", encoding="utf-8")
    merge_metrics(tmp_path, ["r1", "r2", "r9"])
    curves = read_metrics(tmp_path / "metrics.csv")
    assert list(curves) == ["r1", "r2"]
    assert curves["r2"]["q_sum"].tolist() == [0.5, 0.75]       # torn last line dropped
    assert curves["r1"]["collisions"].tolist() == [0, 1]
    assert curves["r1"]["shared"].tolist() == [0, 0]            # no shares file: no share


def test_one_row_per_iteration_a_share_marked_in_its_row(tmp_path: Path) -> None:
    # Prepare: r1 learnt 4 iterations and took writes at 2 and at its last, 4 (which left
    # 10.0 and 20.0); its saved table sums to 20.0
    _robot_metrics(tmp_path, "r1", [1.0, 2.0, 3.0, 4.0])
    _shares(tmp_path, "r1", [(2, "10.0"), (4, "20.0")])
    # Execute
    merge_metrics(tmp_path, ["r1"])
    rows = _rows(tmp_path / "metrics.csv")
    # Assert: 4 rows, the columns in order; the shared rows carry the sum after the write and
    # the learner's before it
    assert list(rows[0]) == list(METRICS_FIELDS)
    assert [(r["iteration"], r["q_sum"], r["shared"], r["q_sum_before_share"]) for r in rows] == [
        ("1", "1.0", "0", ""), ("2", "10.0", "1", "2.0"), ("3", "3.0", "0", ""),
        ("4", "20.0", "1", "4.0")]
    assert [r["cumulative_reward"] for r in rows] == ["1.0", "2.0", "3.0", "4.0"]
    cur = read_metrics(tmp_path / "metrics.csv")["r1"]
    assert cur["iteration"].tolist() == [1, 2, 3, 4]
    assert cur["q_sum"].tolist() == [1.0, 10.0, 3.0, 20.0]
    assert cur["shared"].tolist() == [0, 1, 0, 1]
    assert [None if math.isnan(v) else v for v in cur["q_sum_before_share"]] == \
        [None, 2.0, None, 4.0]


def test_writes_in_one_iteration_are_counted_and_the_last_one_kept(tmp_path: Path) -> None:
    # two writes landed after the robot's last iteration (late rounds), one at iteration 0
    _robot_metrics(tmp_path, "r1", [1.0, 2.0])
    _shares(tmp_path, "r1", [(0, "7.0"), (2, "5.0"), (2, "6.0")])
    merge_metrics(tmp_path, ["r1"])
    cur = read_metrics(tmp_path / "metrics.csv")["r1"]
    assert cur["iteration"].tolist() == [1, 2]      # the write at 0 has no row: shares file only
    assert cur["shared"].tolist() == [0, 2] and cur["q_sum"].tolist() == [1.0, 6.0]
    assert cur["q_sum_before_share"][1] == 2.0


def test_shares_without_a_sum_take_the_saved_tables(tmp_path: Path) -> None:
    # Prepare: shares of an older robot host (no q_sum column); the table it saved at the
    # first share (tables/history/) and its final table
    _robot_metrics(tmp_path, "r1", [1.0, 2.0, 3.0, 4.0])
    _shares(tmp_path, "r1", [(2, ""), (3, ""), (4, "")],
            header=SHARES_HEADER.replace(",q_sum", ""))
    (tmp_path / "tables" / "history").mkdir(parents=True)
    np.save(tmp_path / "tables" / "history" / "r1_it2.npy", np.full((2, 2), 2.5))   # 10.0
    np.save(tmp_path / "tables" / "r1.npy", np.full((2, 2), 5.0))                    # 20.0
    # Execute
    merge_metrics(tmp_path, ["r1"])
    cur = read_metrics(tmp_path / "metrics.csv")["r1"]
    # Assert: the snapshot's sum at 2, the final table's at the last row; at 3 nothing says
    # what the write left: the learner's sum stays, with no sum before the share
    assert cur["shared"].tolist() == [0, 1, 1, 1]
    assert cur["q_sum"].tolist() == [1.0, 10.0, 3.0, 20.0]
    assert cur["q_sum_before_share"][1] == 2.0 and cur["q_sum_before_share"][3] == 4.0
    assert math.isnan(cur["q_sum_before_share"][2])


def test_read_an_older_file_its_last_share_row_folded(tmp_path: Path) -> None:
    # Prepare: metrics.csv as written before the shared column: r1's curve closed by a second
    # row at its last iteration (its saved table's sum), r2's without (the share left its sum)
    path = tmp_path / "metrics.csv"
    path.write_text("robot,iteration,q_sum,cumulative_reward,collisions\n"
                    "r1,1,0.5,1.0,0\nr1,2,0.75,2.0,1\nr1,2,0.6,2.0,1\n"
                    "r2,1,0.25,0.5,0\nr2,2,0.5,1.5,0\n", encoding="utf-8")
    # Execute
    curves = read_metrics(path)
    # Assert: one entry per iteration; the folded row gives the sum the robot ended with
    r1, r2 = curves["r1"], curves["r2"]
    assert r1["iteration"].tolist() == [1, 2] and r2["iteration"].tolist() == [1, 2]
    assert r1["q_sum"].tolist() == [0.5, 0.6] and r1["q_sum_before_share"][1] == 0.75
    assert r1["shared"].tolist() == [0, 1] and r2["shared"].tolist() == [0, 0]
    assert r1["cumulative_reward"].tolist() == [1.0, 2.0]


@pytest.mark.parametrize("text, line", [
    # the older format: a repeat that is not a last-share row (another reward)
    ("robot,iteration,q_sum,cumulative_reward,collisions\n"
     "r1,1,0.5,1.0,0\nr1,2,0.75,2.0,1\nr1,2,0.6,3.0,1\n", 4),
    # the older format: the same row three times
    ("robot,iteration,q_sum,cumulative_reward,collisions\n"
     "r1,1,0.5,1.0,0\nr1,1,0.6,1.0,0\nr1,1,0.7,1.0,0\n", 4),
    # the new format: any repeat
    (",".join(METRICS_FIELDS) + "\nr1,1,0.5,1.0,0,0,\nr1,1,0.6,1.0,0,1,0.5\n", 3),
])
def test_a_repeated_robot_and_iteration_is_an_error(tmp_path: Path, text: str,
                                                    line: int) -> None:
    path = tmp_path / "metrics.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(MetricsFormatError) as err:
        read_metrics(path)
    assert err.value.line == line and "robot r1 iteration" in str(err.value)
    assert isinstance(err.value, ValueError)       # callers that catch ValueError still do


def test_a_file_without_a_column_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "metrics.csv"
    path.write_text("robot,iteration,q_sum\nr1,1,0.5\n", encoding="utf-8")
    with pytest.raises(MetricsFormatError, match="no column cumulative_reward, collisions"):
        read_metrics(path)
