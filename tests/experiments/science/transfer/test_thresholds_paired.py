"""The transfer study's per-arena thresholds (derived from reference runs in each unseen arena,
or given) and the paired bootstrap of censored times to the threshold, on hand-computed
numbers; the unpaired bootstrap of the same phases as the control that cannot see the
effect."""

from __future__ import annotations

import json
import math
from concurrent.futures import ProcessPoolExecutor

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.cli.transfer import thresholds_arg
from dfrl.experiments.science.transfer.claims import (
    censored_difference,
    claim,
    paired_censored_difference,
)
from dfrl.experiments.science.transfer.study import StudyOptions
from dfrl.experiments.science.transfer.thresholds import (
    level_points,
    reference_job,
    threshold_from,
    thresholds_for,
)

FED, CTRL = "federated_average", "standalone_r1"
BUDGET = 2000.0
# per source seed: the h1 phase reaches the threshold, the h2 phase never does (censored at
# the budget), under both sources; the federated h1 times are 50, 50 and 200 shorter
FED_H1, CTRL_H1 = [250.0, 450.0, 700.0], [300.0, 500.0, 900.0]


def phases(h1: list[float]) -> list[tuple[list[float], list[bool]]]:
    return [([t, BUDGET], [True, False]) for t in h1]


def test_paired_censored_difference_by_hand():
    """Every resample of seeds pools 3 reached and 3 censored phases a side; KM falls to 1/2
    at the third event, so each side's median is the largest h1 time among the drawn seeds:
    700 - 900 = -200 when seed 3 is drawn (19 of 27 draws), else 450 - 500 or 250 - 300 =
    -50 (8 of 27). So the interval is [-200, -50], the estimate (all seeds) -200."""
    d = paired_censored_difference(phases(FED_H1), phases(CTRL_H1), resamples=2000, seed=1)
    assert (d.estimate, d.low, d.high, d.known, d.n) == (-200.0, -200.0, -50.0, "exact", 3)
    assert set(d.draws[:, 0]) == set(d.draws[:, 1]) == {-200.0, -50.0}
    assert (d.draws[:, 0] == -50.0).mean() == pytest.approx(8 / 27, abs=0.03)
    assert d.p_value() == 0.0


def test_control_unpaired_resampling_cannot_see_it():
    """The same phases resampled on their own: in 22 of 64 draws a side has 4 or more of its
    6 phases censored, its median beyond the budget, so the upper end is open."""
    fed = ([*FED_H1, BUDGET, BUDGET, BUDGET], [True] * 3 + [False] * 3)
    ctrl = ([*CTRL_H1, BUDGET, BUDGET, BUDGET], [True] * 3 + [False] * 3)
    d = censored_difference(fed, ctrl, 3, resamples=2000, seed=1)
    assert d.estimate == -200.0 and d.high == math.inf and d.low == -math.inf
    assert d.detectable() == math.inf


def rows(ctrl_seeds=(1, 2, 3)) -> list[dict]:
    out = []
    for cond, h1, seeds in ((FED, FED_H1, (1, 2, 3)), (CTRL, CTRL_H1, ctrl_seeds)):
        for s, t in zip(seeds, h1):
            for arena, time, ok in (("h1", t, True), ("h2", BUDGET, False)):
                out.append(
                    {
                        "condition": cond,
                        "source_seed": s,
                        "pair_seed": s,
                        "arena": arena,
                        "target_seed": 1,
                        "collisions_per_1000": 1.0,
                        "time_to_threshold": time,
                        "reached": ok,
                    }
                )
    return out


def test_claim_pairs_censored_times_of_matched_sources():
    paired = claim(rows(), FED, CTRL, "time_to_threshold", resamples=2000)
    assert paired.method == "censored, paired (KM medians)" and paired.censored == (3, 3)
    assert (paired.estimate.low, paired.estimate.high) == (-200.0, -50.0)
    assert paired.judgement.words() == "holds"
    unpaired = claim(rows(ctrl_seeds=(4, 5, 6)), FED, CTRL, "time_to_threshold", resamples=2000)
    assert unpaired.method == "censored (KM medians)" and unpaired.estimate.high == math.inf
    # unpaired, most resamples leave a median beyond the budget: open at both ends, no verdict
    assert unpaired.words().startswith("cannot judge (open at both ends")


def test_paired_needs_the_same_seeds():
    with pytest.raises(ValueError, match="same seeds"):
        paired_censored_difference(phases(FED_H1), phases(CTRL_H1[:2]))


def test_derived_threshold_by_hand():
    th = threshold_from("h2", [0.4, 0.6, 0.8], 0.75, 8000)
    assert th.value == pytest.approx(0.45) and th.level == pytest.approx(0.6)
    assert not th.given and th.origin().startswith(
        "0.75 x 0.6 = 0.45 (the mean level of 3 reference"
    )
    assert level_points(8000) == [4000, 5000, 6000, 7000, 8000]
    for levels, fraction in (([], 0.75), ([0.5, math.nan], 0.75), ([0.5], 0.0), ([0.5], 1.5)):
        with pytest.raises(ValueError):
            threshold_from("h2", levels, fraction, 8000)


def test_thresholds_derived_from_reference_runs_or_given():
    """h1 derived from two real reference runs (80 steps, the mean score at 40, 50, 60, 70,
    80), h2 given; the same seeds give the same runs."""
    levels = [reference_job("h1", k, 80, 20, 20) for k in (1, 2)]
    assert levels == [reference_job("h1", k, 80, 20, 20) for k in (1, 2)]
    with ProcessPoolExecutor(2) as pool:
        th = thresholds_for(["h1", "h2"], {"h2": 0.3}, 0.5, 80, 2, 20, 20, pool)
    assert th["h1"].value == pytest.approx(0.5 * (levels[0] + levels[1]) / 2)
    assert th["h1"].levels == tuple(levels)
    assert th["h2"].given and th["h2"].value == 0.3 and th["h2"].origin() == "given 0.3"


def test_threshold_options():
    opts = StudyOptions(targets=("h1", "h2"), threshold=0.5, arena_thresholds=(("h2", 0.3),))
    assert opts.given_thresholds() == {"h1": 0.5, "h2": 0.3}
    assert StudyOptions(targets=("h1", "h2")).given_thresholds() == {}
    with pytest.raises(ValueError, match="not among the target arenas"):
        StudyOptions(targets=("h1",), arena_thresholds=(("h2", 0.3),))
    assert thresholds_arg(["0.5", "h2=0.3"]) == {
        "threshold": 0.5,
        "arena_thresholds": (("h2", 0.3),),
    }
    with pytest.raises(ValueError, match="neither"):
        thresholds_arg(["h2=high"])
    with pytest.raises(ValueError, match="one SCORE"):
        thresholds_arg(["0.5", "0.6"])


def test_study_uses_each_arenas_threshold(tmp_path, capsys):
    """A tiny study on pybullet: h1's threshold derived (reference runs of 40 steps), h2's
    given; each is lifted above every iteration-0 score in its arena when one starts there;
    every learning phase records its arena's, its time is the first of two evaluations in a
    row at or above it, and the report lists both."""
    out = tmp_path / "study"
    assert (
        main(
            [
                "transfer-study",
                "--seeds",
                "1",
                "2",
                "3",
                "--targets",
                "h1",
                "h2",
                "--iterations",
                "40",
                "--respite",
                "20",
                "--learn",
                "60",
                "--eval-every",
                "20",
                "--eval-steps",
                "20",
                "--resamples",
                "200",
                "--jobs",
                "2",
                "--sim",
                "pybullet",
                "--threshold",
                "h2=0.05",
                "--threshold-iterations",
                "40",
                "--threshold-runs",
                "2",
                "--threshold-fraction",
                "0.5",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    doc = json.loads((out / "transfer_study.json").read_text())
    level = sum(reference_job("h1", k, 40, 20, 200) for k in (1, 2)) / 2
    want = {"h1": 0.5 * level, "h2": 0.05}
    for r in doc["rows"]:
        starts = [q["start_score"] for q in doc["rows"] if q["arena"] == r["arena"]]
        assert r["threshold_base"] == pytest.approx(want[r["arena"]])
        assert r["threshold"] == pytest.approx(max(want[r["arena"]], max(starts)))
        assert r["threshold"] > max(starts)
        above = [s >= r["threshold"] for _, s in r["scores"]]
        first = next((i for i in range(len(above) - 1) if above[i] and above[i + 1]), None)
        if first is None:
            assert not r["reached"] and r["time_to_threshold"] == 60
        else:
            assert r["reached"] and r["time_to_threshold"] == r["scores"][first][0] > 0
    text = (out / "transfer_study.md").read_text()
    assert "| h2 | " in text and "given 0.05" in text and "| h1 | " in text
    assert "reference runs" in text
    assert "threshold in h1:" in capsys.readouterr().err
