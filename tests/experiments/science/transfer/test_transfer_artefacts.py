"""``dfrl transfer-study`` without artefacts (issue 34), on hand-computed numbers: no phase at
the threshold from the start (the floor), the score while learning where the time cannot
see, no verdict from a degenerate interval, learning-phase seeds of each source seed's own."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dfrl.experiments.science.statistics import holm
from dfrl.experiments.science.transfer.claims import CensoredDifference, claim, claims, degenerate
from dfrl.experiments.science.transfer.study import (
    PHASE_EVAL_OFFSET,
    StudyOptions,
    pair_seed,
    phase_seeds,
    with_times,
)
from dfrl.experiments.science.transfer.thresholds import Threshold, lift, time_to_threshold

FED, CTRL = "federated_average", "standalone_r1"
GRID = [0, 100, 200, 300, 400]


def phase(
    condition: str, seed: int, scores: list[float], collisions: float = 1.0, arena: str = "h1"
) -> dict:
    """A learning-phase row as :func:`target_job` writes it (before :func:`with_times`)."""
    curve = list(zip(GRID, scores))
    area = sum((b - a) * (x + y) / 2 for (a, x), (b, y) in zip(curve, curve[1:])) / GRID[-1]
    train, ev = phase_seeds(seed, 1)
    return {
        "condition": condition,
        "source_seed": seed,
        "pair_seed": seed,
        "arena": arena,
        "target_seed": 1,
        "phase_seed": train,
        "eval_seed": ev,
        "collisions_per_1000": collisions,
        "score_auc": area,
        "start_score": scores[0],
        "scores": curve,
        "collisions": [(g, 0) for g in GRID],
    }


# -- the floor ---------------------------------------------------------------------------------
def test_lift_puts_the_threshold_above_every_start():
    # Prepare: a derived 0.5; phases start at 0.3, 0.62 and 0.55
    base = Threshold("h1", 0.5, False, 0.75, (0.6, 0.7), 8000)
    # Execute
    th = lift(base, [0.3, 0.62, 0.55])
    # Assert: just above 0.62, the base kept for the report
    assert th.value == np.nextafter(0.62, 1.0) and th.value > 0.62 and th.base == 0.5
    assert th.lifted and th.best_start == 0.62 and th.phases == 3
    assert "lifted to just above 0.62, the best iteration-0 score of the 3 learning" in th.origin()
    # a phase that starts at the best start and stays there never reaches it: at the base
    # threshold it had the time 0 without learning anything
    flat = [(0, 0.62), (100, 0.62), (200, 0.62)]
    assert time_to_threshold(flat, th.base, 2, 200) == (0.0, True)
    assert time_to_threshold(flat, th.value, 2, 200) == (200.0, False)
    # a threshold above every start stays as it is
    high = lift(Threshold("h1", 0.9, True), [0.3, 0.62])
    assert high.value == 0.9 and not high.lifted and high.origin().startswith("given 0.9; ")
    with pytest.raises(ValueError, match="finite"):
        lift(base, [])


def test_time_to_threshold_by_hand():
    scores = [(0, 0.1), (100, 0.5), (200, 0.3), (300, 0.5), (400, 0.6)]
    assert time_to_threshold(scores, 0.5, 2, 400) == (300.0, True)  # 100 alone: one crossing
    assert time_to_threshold(scores, 0.5, 1, 400) == (100.0, True)
    assert time_to_threshold(scores, 0.6, 2, 400) == (400.0, False)  # the last point alone
    with pytest.raises(ValueError):
        time_to_threshold(scores, 0.5, 0, 400)


def test_no_phase_has_the_time_zero_after_with_times():
    """Every phase starts at or above the base threshold 0.5 (the floor: all times 0 before);
    after the lift none is at the threshold at iteration 0."""
    rows = [phase(FED, 1, [0.6, 0.7, 0.8, 0.8, 0.8]), phase(CTRL, 1, [0.55, 0.55, 0.6, 0.6, 0.6])]
    timed, lifted = with_times(rows, {"h1": Threshold("h1", 0.5, True)}, confirm=2, budget=400)
    assert lifted["h1"].value == np.nextafter(0.6, 1.0)
    assert [(r["time_to_threshold"], r["reached"]) for r in timed] == [
        (100.0, True),
        (400.0, False),
    ]
    assert all(r["threshold_base"] == 0.5 and r["start_score"] < r["threshold"] for r in timed)


def test_the_score_while_learning_sees_what_the_time_cannot():
    """Both sources start above the threshold 0.5 in every seed, the federated one learns
    more. At the unlifted threshold every time is 0: differences 0 in every seed, a zero-width
    interval (the old code called it refuted, p = 1); now cannot judge. The score while
    learning (areas: federated (0.65 + (0.7 + t) / 2 + 2 t) / 4 = 0.75, 0.78125, 0.8125 for t =
    0.8, 0.85, 0.9; control (0.6 + 0.6 + 0.625 + 0.625) / 4 = 0.6125) holds."""
    rows = []
    for s, top in ((1, 0.8), (2, 0.85), (3, 0.9)):
        rows.append(phase(FED, s, [0.6, 0.7, top, top, top]))
        rows.append(phase(CTRL, s, [0.6, 0.6, 0.6, 0.65, 0.6]))
    at_base = [{**r, "time_to_threshold": 0.0, "reached": True} for r in rows]
    time = claim(at_base, FED, CTRL, "time_to_threshold")
    assert time.method == "paired" and (time.estimate.mean, time.estimate.half) == (0.0, 0.0)
    assert time.words() == "cannot judge (zero width: the difference is 0 in every seed)"
    assert math.isnan(time.judgement.p)
    score = claim(at_base, FED, CTRL, "score_auc")
    # differences 0.1375, 0.16875, 0.2: mean 0.16875, sd 0.03125, se 0.03125 / sqrt(3)
    assert score.estimate.mean == pytest.approx(0.16875)
    assert score.estimate.half == pytest.approx(4.302653 * 0.03125 / math.sqrt(3), rel=1e-5)
    assert score.judgement.side == "above" and score.words() == "holds"
    lifted, _ = with_times(rows, {"h1": Threshold("h1", 0.5, True)}, confirm=2, budget=400)
    # lifted just above 0.6: federated at 100 in every seed, the control at 300 only when its
    # 0.65 holds two evaluations in a row (never): censored in every seed
    assert [r["time_to_threshold"] for r in lifted] == [100.0, 400.0] * 3
    assert not any(r["reached"] for r in lifted if r["condition"] == CTRL)


# -- degenerate intervals ----------------------------------------------------------------------
def test_degenerate_intervals_by_hand():
    zero = CensoredDifference(5.0, 5.0, 5.0, 3, "exact", np.array([[5.0, 5.0], [4.0, 6.0]]))
    assert degenerate(zero) == "zero width: every resample's difference is 5"
    same = CensoredDifference(
        -100.0, -math.inf, -100.0, 3, "at most", np.array([[-math.inf, -100.0]] * 4)
    )
    assert degenerate(same) == "every resample gives the same difference, [-inf, -100]"
    spread = CensoredDifference(
        -100.0, -200.0, 50.0, 3, "exact", np.array([[-200.0, -200.0], [50.0, 50.0]])
    )
    assert degenerate(spread) is None


def every_condition(collisions: dict[str, list[float]]) -> list[dict]:
    """Rows of every condition of the default options, three seeds, after :func:`with_times`
    (a threshold reached by no phase, so the times are censored)."""
    opts = StudyOptions(source_seeds=(1, 2, 3), targets=("h1",))
    rows = [
        phase(c, s, [0.1, 0.2, 0.3, 0.3, 0.3], collisions[c][s - 1])
        for c in opts.conditions
        for s in (1, 2, 3)
    ]
    return with_times(rows, {"h1": Threshold("h1", 0.9, True)}, 2, 400)[0]


def test_a_degenerate_claim_has_no_p_and_leaves_the_holm_family():
    """standalone_r1 collides exactly 1 more than federated in every seed: zero width, no
    verdict, and the other five collision claims and the five score claims (all differences
    0: zero width too) are adjusted among themselves only."""
    opts = StudyOptions(source_seeds=(1, 2, 3), targets=("h1",))
    fed = [5.0, 6.0, 7.0]
    coll = {
        c: [x + 1.0 + (k * 0.3 * i if c != "standalone_r1" else 0.0) for i, x in enumerate(fed)]
        for k, c in enumerate(opts.conditions)
    }
    coll[FED] = fed
    found = claims(every_condition(coll), opts, resamples=200)
    by = {(c.measure, c.control): c for c in found}
    r1 = by["collisions_per_1000", "standalone_r1"]
    assert r1.words() == "cannot judge (zero width: the difference is -1 in every seed)"
    assert math.isnan(r1.judgement.p) and math.isnan(r1.judgement.p_adjusted)
    assert r1.to_dict()["p_holm"] is None and r1.to_dict()["reason"].startswith("zero width")
    judged = [c for c in found if c.family == "primary" and not math.isnan(c.judgement.p)]
    assert [c.control for c in judged] == [f"standalone_r{k}" for k in (2, 3, 4, 5)] + ["zeros"]
    assert [c.judgement.p_adjusted for c in judged] == pytest.approx(
        holm([c.judgement.p for c in judged])
    )
    scores = [c for c in found if c.measure == "score_auc"]
    assert all(c.words().startswith("cannot judge (zero width") for c in scores)
    # every time censored on both sides: each resample allows any difference
    times = [c for c in found if c.measure == "time_to_threshold"]
    assert all(
        c.words() == "cannot judge (every resample gives the same difference, [-inf, inf])"
        for c in times
    )


# -- learning-phase seeds ----------------------------------------------------------------------
def test_phase_seeds_are_the_source_seeds_own():
    """Paired within a source seed (every condition the same seeds), independent across
    seeds: no two (source seed, target seed) share a training or an evaluation seed."""
    opts = StudyOptions(source_seeds=(1, 2, 3))
    assert phase_seeds(1, 1) == (1_001_001, 1_001_501)
    assert {phase_seeds(pair_seed(c, 2, opts), 1) for c in opts.conditions} == {phase_seeds(2, 1)}
    seeds = [x for s in range(40) for t in range(PHASE_EVAL_OFFSET) for x in phase_seeds(s, t)]
    assert len(set(seeds)) == len(seeds)
    unpaired = StudyOptions(source_seeds=(1, 2, 3), unpaired=True)
    assert phase_seeds(pair_seed(CTRL, 1, unpaired), 1) != phase_seeds(
        pair_seed(FED, 1, unpaired), 1
    )
    for bad in ((PHASE_EVAL_OFFSET,), (-1,)):
        with pytest.raises(ValueError, match="target seeds"):
            StudyOptions(target_seeds=bad)
