"""``dfrl transfer-study``: the command end to end on tiny budgets (files, pairing, censoring),
and its claims and verdict words on hand-made numbers."""

from __future__ import annotations

import csv
import json
import math

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.science.statistics import paired, t975, t_quantile, welch
from dfrl.experiments.science.transfer.claims import claim, compare, markdown
from dfrl.experiments.science.transfer.study import StudyOptions

FED = "federated_average"


TINY = [
    "transfer-study",
    "--seeds",
    "1",
    "2",
    "3",
    "--targets",
    "h1",
    "--iterations",
    "40",
    "--respite",
    "20",
    "--learn",
    "40",
    "--eval-every",
    "20",
    "--eval-steps",
    "20",
    "--resamples",
    "200",
    "--jobs",
    "2",
]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("transfer_study")
    assert main(TINY + ["--threshold", "10", "--out", str(out)]) == 0
    return out


def test_same_seeds_same_study(study, tmp_path):
    """Determinism; a threshold given below every score is lifted above every phase's
    iteration-0 score, so no phase is at it from the start (the floor)."""
    assert main(TINY + ["--threshold", "-10", "--out", str(tmp_path)]) == 0
    first = json.loads((study / "transfer_study.json").read_text())["rows"]
    again = json.loads((tmp_path / "transfer_study.json").read_text())["rows"]
    measured = (
        "collisions_per_1000",
        "score_auc",
        "start_score",
        "scores",
        "collisions",
        "phase_seed",
        "eval_seed",
    )
    assert [{k: r[k] for k in measured} for r in again] == [
        {k: r[k] for k in measured} for r in first
    ]
    best = max(r["start_score"] for r in again)
    assert all(r["threshold_base"] == -10 and r["threshold"] > best for r in again)
    assert not any(r["reached"] and r["time_to_threshold"] == 0 for r in again)
    text = (tmp_path / "transfer_study.md").read_text()
    assert "| 21 of 21 | 0 of 21 |" in text  # at the unlifted threshold, at the one used


def test_learning_phases_are_seeded_per_source_seed(study):
    """No pseudo-replication: the zeros source has one table for every source seed, so its
    learning phases differ between seeds only through their seeds; they must differ (with one
    target seed shared by every source seed they were the same phase, 10.2 +- 0). Within a
    source seed every source learns from the same seeds (paired)."""
    rows = json.loads((study / "transfer_study.json").read_text())["rows"]
    zeros = [(r["scores"], r["collisions"]) for r in rows if r["condition"] == "zeros"]
    assert len(zeros) == 3
    assert zeros[0] != zeros[1] and zeros[0] != zeros[2] and zeros[1] != zeros[2]
    seeds = {
        s: {(r["phase_seed"], r["eval_seed"]) for r in rows if r["source_seed"] == s}
        for s in (1, 2, 3)
    }
    assert all(len(v) == 1 for v in seeds.values())  # paired within a seed
    assert len(set.union(*seeds.values())) == 3  # independent across seeds


def test_study_writes_its_files(study):
    for name in ("transfer_study.md", "transfer_study.json", "tidy.csv", "provenance.json"):
        assert (study / name).stat().st_size > 0, name
    prov = json.loads((study / "provenance.json").read_text())
    assert {"dfrl", "git", "python", "numpy", "command", "started"} <= set(prov)
    with open(study / "tidy.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["run", "seed", "condition", "robot", "iteration", "metric", "value"]
    runs = {r["run"] for r in rows}
    assert runs == {FED, "zeros"} | {f"standalone_r{k}" for k in range(1, 6)}
    # the score on the grid 0, 20, 40 of every learning phase (a threshold never reached)
    assert sorted({int(r["iteration"]) for r in rows if r["metric"] == "score@h1"}) == [0, 20, 40]


def test_matched_sources_get_paired_intervals(study):
    doc = json.loads((study / "transfer_study.json").read_text())
    coll = [c for c in doc["claims"] if c["measure"] == "collisions_per_1000"]
    assert {c["control"] for c in coll} == {f"standalone_r{k}" for k in range(1, 6)} | {"zeros"}
    assert all(c["method"] == "paired" and c["n"] == 3 for c in coll)
    # the paired interval recomputed from the rows
    rows = doc["rows"]
    val = {(r["condition"], r["source_seed"]): r["collisions_per_1000"] for r in rows}
    ref = paired([val[FED, s] for s in (1, 2, 3)], [val["standalone_r3", s] for s in (1, 2, 3)])
    c = next(c for c in coll if c["control"] == "standalone_r3")
    assert c["estimate"] == pytest.approx(ref.mean)
    if math.isfinite(ref.half) and ref.half > 0:
        assert c["high"] - c["low"] == pytest.approx(2 * ref.half)


def test_a_run_that_never_reaches_the_threshold_is_censored(study):
    doc = json.loads((study / "transfer_study.json").read_text())
    assert all(not r["reached"] and r["time_to_threshold"] == 40 for r in doc["rows"])
    times = [c for c in doc["claims"] if c["measure"] == "time_to_threshold"]
    assert all(
        c["method"] == "censored, paired (KM medians)" and c["censored"] == [3, 3] for c in times
    )
    # every resample allows any difference: no verdict, no p, outside the Holm family
    assert all(
        c["known"] == "unknown"
        and c["p"] is None
        and c["p_holm"] is None
        and c["verdict"] == "cannot judge (every resample gives the same difference, [-inf, inf])"
        for c in times
    )
    assert "3 of 3 censored" in (study / "transfer_study.md").read_text()
    with open(study / "tidy.csv", newline="") as fh:
        reached = [float(r["value"]) for r in csv.DictReader(fh) if r["metric"] == "reached@h1"]
    assert len(reached) == 21 and set(reached) == {0.0}


def test_from_json_judges_the_same_phases_again(study, tmp_path, capsys):
    again = tmp_path / "again"
    rc = main(
        [
            "transfer-study",
            "--from-json",
            str(study / "transfer_study.json"),
            "--resamples",
            "200",
            "--out",
            str(again),
        ]
    )
    assert rc == 0
    first = json.loads((study / "transfer_study.json").read_text())
    second = json.loads((again / "transfer_study.json").read_text())
    assert second["claims"] == first["claims"] and second["rows"] == first["rows"]
    assert (again / "tidy.csv").read_text() == (study / "tidy.csv").read_text()
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["transfer-study", "--from-json", str(bad)]) == 2
    assert "bad.json" in capsys.readouterr().err


# -- hand-made numbers -----------------------------------------------------------------------
def rows_of(fed: list[float], ctrl: list[float], ctrl_seeds=(1, 2, 3), times=None):
    """Learning-phase rows: collisions of the federated source and standalone_r1 per seed;
    ``times``: (time, reached) per phase, the same for both."""
    out = []
    for cond, vals, seeds in ((FED, fed, (1, 2, 3)), ("standalone_r1", ctrl, ctrl_seeds)):
        for i, (s, v) in enumerate(zip(seeds, vals)):
            t, ok = times[i] if times else (100.0, True)
            out.append(
                {
                    "condition": cond,
                    "source_seed": s,
                    "pair_seed": s,
                    "arena": "h1",
                    "target_seed": 1,
                    "phase_seed": 1_001_001,
                    "eval_seed": 1_001_501,
                    "collisions_per_1000": v,
                    "score_auc": 0.5,
                    "start_score": 0.1,
                    "time_to_threshold": t,
                    "reached": ok,
                    "threshold": 0.4,
                    "threshold_base": 0.4,
                    "threshold_from": "given 0.4",
                    "scores": [(0, 0.1), (1000, 0.9)],
                    "collisions": [(0, 0), (1000, 1)],
                }
            )
    return out


def test_compare_pairs_same_seeds_and_welch_otherwise():
    a, b = {1: 10.0, 2: 20.0, 3: 30.0}, {1: 9.0, 2: 19.5, 3: 28.5}
    iv, how = compare(a, b)
    # differences 1, 0.5, 1.5: mean 1, sd 0.5, half t975(2) x 0.5 / sqrt(3) = 1.2421
    assert how == "paired" and iv.mean == pytest.approx(1.0)
    assert iv.half == pytest.approx(4.302653 * 0.5 / math.sqrt(3), rel=1e-5)
    iv2, how2 = compare(a, {4: 9.0, 5: 19.5, 6: 28.5})
    assert how2 == "Welch" and iv2.half == pytest.approx(
        welch(list(a.values()), [9.0, 19.5, 28.5]).half
    )
    assert iv2.half > 10 * iv.half  # the pairing is what makes the effect visible


def test_verdict_words_on_hand_made_numbers():
    holds = claim(
        rows_of([5.0, 6.0, 7.0], [10.0, 11.2, 11.9]), FED, "standalone_r1", "collisions_per_1000"
    )
    assert holds.method == "paired" and holds.judgement.words() == "holds"
    refuted = claim(
        rows_of([10.0, 11.2, 11.9], [5.0, 6.0, 7.0]), FED, "standalone_r1", "collisions_per_1000"
    )
    assert refuted.judgement.words() == "refuted (effect excluded at 95%)"
    wide = claim(
        rows_of([5.0, 15.0, 4.0], [10.0, 6.0, 9.0]), FED, "standalone_r1", "collisions_per_1000"
    )
    # differences -5, 9, -5: mean -1/3, sd 8.0829, se 4.6667; D = (t975(2) + t(0.8, 2)) x se
    se = math.sqrt(((-5 + 1 / 3) ** 2 * 2 + (9 + 1 / 3) ** 2) / 2 / 3)
    d = (t975(2) + t_quantile(0.8, 2)) * se
    assert (
        wide.judgement.words() == f"not significant at n = 3 (smallest detectable effect {d:.2g})"
    )
    assert wide.estimate.detectable() == pytest.approx(d)
    unpaired = claim(
        rows_of([5.0, 6.0, 7.0], [10.0, 11.2, 11.9], ctrl_seeds=(4, 5, 6)),
        FED,
        "standalone_r1",
        "collisions_per_1000",
    )
    assert unpaired.method == "Welch"


def test_censored_times_use_kaplan_meier_and_are_counted():
    times = [(200.0, True), (1000.0, False), (400.0, True)]
    c = claim(rows_of([1, 2, 3], [1, 2, 3], times=times), FED, "standalone_r1", "time_to_threshold")
    assert (
        c.method == "censored, paired (KM medians)" and c.censored == (1, 1) and c.phases == (3, 3)
    )
    assert c.estimate.estimate == pytest.approx(0.0)  # KM medians 400 - 400
    # a federated source at the threshold from the start (time 0), controls censored late:
    fast = rows_of([1, 2, 3], [1, 2, 3], times=[(0.0, True)] * 3)
    for r in fast[3:]:
        r["time_to_threshold"], r["reached"] = 1000.0, False
    c0 = claim(fast, FED, "standalone_r1", "time_to_threshold")
    assert c0.estimate.known == "at most" and c0.estimate.mean == -1000.0
    # -inf .. 0 - 1000 in every resample: the spread between seeds unseen, so no verdict
    # (it was "holds" with p = 0)
    assert c0.words() == "cannot judge (every resample gives the same difference, [-inf, -1,000])"
    assert math.isnan(c0.judgement.p)
    uncensored = claim(rows_of([1, 2, 3], [1, 2, 3]), FED, "standalone_r1", "time_to_threshold")
    assert uncensored.method == "paired" and uncensored.censored == (0, 0)
    opts = StudyOptions(source_seeds=(1, 2, 3), targets=("h1",))
    rows = rows_of([1, 2, 3], [1, 2, 3], times=times)
    text = markdown(rows, opts, [c], 1.0)
    assert "1 of 3 censored" in text and "censored, paired (KM medians)" in text


@pytest.mark.parametrize("targets", [["nowhere"], ["r3"]])
def test_an_unknown_or_source_arena_is_refused_before_any_training(tmp_path, capsys, targets):
    out = tmp_path / "out"
    rc = main(["transfer-study", "--seeds", "1", "2", "--targets", *targets, "--out", str(out)])
    assert rc == 2
    assert targets[0] in capsys.readouterr().err
    assert not (out / "transfer_study.json").exists()
