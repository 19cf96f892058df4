"""The tidy tables (``tidy/steps.csv``, ``shares.csv``, ``rounds.csv``) from a results folder
written by hand: the rounds and phases of the steps, the robots of each round and their
outcomes, unique keys, and a repeated key refused with its places."""
from __future__ import annotations

import csv
from pathlib import Path

import pandas as pd

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.results.metrics import METRICS_FIELDS
from dfrl.experiments.driver.results.rounds import ROUNDS_FIELDS
from dfrl.experiments.driver.results.tidy import (ROUND_FIELDS, SHARE_FIELDS, STEP_FIELDS,
                                                  TIDY_KEYS, write_tidy_tables)
from dfrl.experiments.robot_host.files import SHARE_FIELDS as ROBOT_SHARE_FIELDS

CONFIG = ExperimentConfig(robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4", "sarsa")))
D1, D2 = "a" * 64, "b" * 64


def _csv(path: Path, fields: tuple[str, ...] | list[str], rows: list[list[object]],
         torn: str = "") -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(fields)
        w.writerows(rows)
        fh.write(torn)


def _folder(out: Path) -> None:
    """r1 written in rounds 1 and 2 (at iterations 2 and 4), r2 in round 1 only: skipped in
    round 2 for a reason holding "; "; r2's metrics end in a torn line."""
    metrics = [["r1", 1, "0.5", "1.0", 0, 0, ""], ["r1", 2, "2.0", "2.0", 0, 1, "1.5"],
               ["r1", 3, "2.5", "3.0", 1, 0, ""], ["r1", 4, "3.0", "4.0", 1, 1, "3.5"],
               ["r2", 1, "0.25", "0.5", 0, 0, ""], ["r2", 2, "2.0", "1.0", 0, 1, "0.75"],
               ["r2", 3, "1.0", "1.5", 0, 0, ""]]
    _csv(out / "metrics.csv", METRICS_FIELDS, metrics, torn="r2,4,1.")
    _csv(out / "shares_r1.csv", ROBOT_SHARE_FIELDS,
         [["r1", 1, 2, "10.5", D1, 1, "fed_x", 1, "2.0"],
          ["r1", 2, 4, "20.5", D2, 2, "fed_x", 1, "3.0"]])
    _csv(out / "shares_r2.csv", ROBOT_SHARE_FIELDS,
         [["r2", 1, 2, "10.6", D1, 1, "fed_x", 1, "2.0"]])
    base = {k: "" for k in ROUNDS_FIELDS}
    fields = list(ROUNDS_FIELDS) + ["digest_r1", "digest_r2", "all_equal"]
    one = {**base, "agent": "fed_x", "round": 1, "start": "10.0", "end": "11.0", "epoch": 1,
           "method": "average", "visited": "r1 r2", "written": "r1 r2", "digest_r1": D1,
           "digest_r2": D1, "all_equal": "true", "reconstructed": "false"}
    two = {**one, "round": 2, "visited": "r1", "written": "r1", "digest_r1": D2,
           "digest_r2": "", "skipped": "r2: unreachable; retried twice"}
    _csv(out / "rounds.csv", fields, [[row[f] for f in fields] for row in (one, two)])


def _read(out: Path, name: str) -> list[dict[str, str]]:
    with open(out / "tidy" / f"{name}.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_tables_from_a_folder(tmp_path: Path) -> None:
    # Prepare
    _folder(tmp_path)
    # Execute
    written, problems = write_tidy_tables(tmp_path, CONFIG, ["r1", "r2"])
    # Assert
    assert problems == [] and [p.name for p in written] == ["steps.csv", "shares.csv",
                                                            "rounds.csv"]
    steps = _read(tmp_path, "steps")
    assert list(steps[0]) == list(STEP_FIELDS)
    r1 = [s for s in steps if s["robot"] == "r1"]
    assert [s["round"] for s in r1] == ["0", "1", "1", "2"]
    assert [s["phase"] for s in r1] == ["learn", "share", "learn", "share"]
    # the numbers are metrics.csv's text; before the share = q_sum where there was none
    assert [s["q_sum"] for s in r1] == ["0.5", "2.0", "2.5", "3.0"]
    assert [s["q_sum_before_share"] for s in r1] == ["0.5", "1.5", "2.5", "3.5"]
    assert {(s["algo"], s["arena"], s["agent"]) for s in r1} == {("qlearning", "r1", "fed_x")}
    r2 = [s for s in steps if s["robot"] == "r2"]
    assert [s["iteration"] for s in r2] == ["1", "2", "3"]          # the torn line left out
    assert [s["round"] for s in r2] == ["0", "1", "1"] and r2[0]["algo"] == "sarsa"
    shares = _read(tmp_path, "shares")
    assert list(shares[0]) == list(SHARE_FIELDS)
    assert [(s["robot"], s["share_index"], s["round"], s["digest"]) for s in shares] == [
        ("r1", "1", "1", D1), ("r1", "2", "2", D2), ("r2", "1", "1", D1)]
    assert shares[2]["arena"] == "r4" and shares[2]["wall_time"] == "10.6"
    rounds = _read(tmp_path, "rounds")
    assert list(rounds[0]) == list(ROUND_FIELDS)
    assert [(r["round"], r["robot"], r["outcome"], r["digest"]) for r in rounds] == [
        ("1", "r1", "written", D1), ("1", "r2", "written", D1), ("2", "r1", "written", D2),
        ("2", "r2", "skipped", "")]
    assert rounds[3]["reason"] == "unreachable; retried twice"
    # one line each into pandas; pivoting on the keys gives the wide tables back
    for name, key in TIDY_KEYS.items():
        df = pd.read_csv(tmp_path / "tidy" / f"{name}.csv")
        assert not df.duplicated(list(key)).any(), name
    wide = pd.read_csv(tmp_path / "tidy" / "steps.csv").pivot(
        index="iteration", columns="robot", values="q_sum")
    assert wide["r1"].tolist() == [0.5, 2.0, 2.5, 3.0] and pd.isna(wide.loc[4, "r2"])
    digests = pd.read_csv(tmp_path / "tidy" / "rounds.csv").pivot(
        index=["agent", "round"], columns="robot", values="digest")
    assert digests.loc[("fed_x", 1)].tolist() == [D1, D1]


def test_repeated_key_is_refused_with_its_places(tmp_path: Path) -> None:
    # Prepare: r1's shares file holds share 2 twice (the control: the other tables are fine)
    _folder(tmp_path)
    with open(tmp_path / "shares_r1.csv", "a", encoding="utf-8") as fh:
        fh.write(f"r1,2,4,20.7,{D2},2,fed_x,1,3.0\n")
    # Execute
    written, problems = write_tidy_tables(tmp_path, CONFIG, ["r1", "r2"])
    # Assert
    assert [p.name for p in written] == ["steps.csv", "rounds.csv"]
    assert not (tmp_path / "tidy" / "shares.csv").exists()
    assert problems == ["tidy table not written: tidy/shares.csv: shares_r1.csv:4: robot r1, "
                        "share_index 2 as in shares_r1.csv:3; the key (robot, share_index) "
                        "must be unique"]


def test_bad_iteration_is_located(tmp_path: Path) -> None:
    _folder(tmp_path)
    text = (tmp_path / "metrics.csv").read_text().replace("r1,3,", "r1,three,")
    (tmp_path / "metrics.csv").write_text(text)
    written, problems = write_tidy_tables(tmp_path, CONFIG, ["r1", "r2"])
    assert "steps.csv" not in [p.name for p in written]
    assert problems == ["tidy table not written: metrics.csv:4: iteration 'three' is not an "
                        "integer"]
