"""``dfrl speedup``: the design (arenas per condition, N = 1 shared), the held score time, the
federation observer, determinism with a seed, censored rows in the analysis, and a tiny run of
the command end to end with its output files."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.science.reference_store import reference_table
from dfrl.experiments.science.statistics import Outcome
from dfrl.experiments.science.studies.fedsim import federate
from dfrl.experiments.science.studies.speedup import (
    REFERENCE,
    SpeedupOptions,
    arenas,
    run_one,
    runs_needed,
    score_time,
)
from dfrl.experiments.science.studies.speedup_report import analyse, verdict
from dfrl.robots.training import TrainerConfig

TINY = dict(
    iterations=300,
    share_every=100,
    grid=100,
    score_every=300,
    score_hold=1,
    eval_steps=60,
    episode_steps=30,
    resamples=200,
    jobs=1,
)


def test_arenas_per_condition_and_n1_run_once() -> None:
    assert arenas("homogeneous", 3) == ("r1", "r1", "r1")
    assert arenas("heterogeneous", 7) == ("r1", "r2", "r3", "r4", "r5", "r1", "r2")
    assert arenas("homogeneous", 1) == arenas("heterogeneous", 1) == ("r1",)
    with pytest.raises(ValueError):
        arenas("mixed", 2)
    opts = SpeedupOptions(robots=(1, 2), seeds=(1, 2, 3))
    # 3 seeds x (N = 1 once, N = 2 homogeneous, N = 2 heterogeneous); smallest N first
    keys = runs_needed(opts)
    assert len(keys) == 9 and len(keys[0][0]) == 1 and len(keys[-1][0]) == 2
    with pytest.raises(ValueError, match="including 1"):
        SpeedupOptions(robots=(2, 5)).check()
    with pytest.raises(ValueError, match="multiple of grid"):
        SpeedupOptions(grid=300, score_every=500).check()


def test_score_time_needs_the_threshold_held() -> None:
    its, scores = [100, 200, 300, 400], [0.8, 0.2, 0.8, 0.9]
    assert score_time(its, scores, 0.7, 1) == 100  # the first crossing
    assert score_time(its, scores, 0.7, 2) == 300  # the jump at 100 does not hold
    assert score_time(its, scores, 0.95, 1) is None  # never: censored


def test_observer_stops_the_federation_and_final_share_can_be_off() -> None:
    cfgs = [TrainerConfig(arena="r1", seed=s, iterations=300) for s in (1, 2)]
    seen: list[int] = []
    fed = federate(
        cfgs, 300, 100, observe=lambda it, tr: seen.append(it) or it >= 200, observe_every=50
    )
    assert seen == [50, 100, 150, 200] and fed.iterations == 200
    assert fed.q_sum is not None and fed.q_sum.shape == (2, 200)
    # budget 250 with shares every 100: by default one more share at 250 (the last round);
    # final_share=False keeps the shares at 100 and 200 only
    apart = federate(cfgs, 250, 100, final_share=False, snapshot_every=1)
    assert sorted(apart.snapshots) == [100, 200]
    with pytest.raises(ValueError):
        federate(cfgs, 100, 50, observe=lambda it, tr: False)


def test_run_one_is_deterministic_with_its_seed() -> None:
    ref = reference_table(**REFERENCE)
    opts = SpeedupOptions(targets=(0.999, 0.2), **TINY)
    a = run_one(("r1", "r2"), 4, opts, ref)
    b = run_one(("r1", "r2"), 4, opts, ref)
    c = run_one(("r1", "r2"), 5, opts, ref)
    assert a["error"] == b["error"] and a["score"] == b["score"] and a["times"] == b["times"]
    assert a["error"] != c["error"]  # another seed, another run
    assert a["grid"] == [100, 200, 300] and a["score_iterations"] == [300]
    assert a["times"]["error<=0.999"] == 100  # the zero table is at 1
    assert a["times"]["error<=0.2"] is None  # far below one run's floor: censored
    assert a["iterations"] == 300  # not every target reached: no stop


def _run(n: int, seed: int, time: int | None, budget: int = 12_000) -> dict:
    return {
        "robots": n,
        "seed": seed,
        "budget": budget,
        "times": {"error<=0.7": time, "score>=0.7": time},
    }


def test_analysis_keeps_censored_runs_censored() -> None:
    # T(1) censored at the budget in every seed, T(2) = 8,000 and T(5) = 8,000: T(1)/T(N) is
    # at least 1.5: "any speed-up" holds at N = 2 and N = 5, "linear" (> 0.5 N: 1 and 2.5)
    # holds at N = 2 and is not significant at N = 5 (it would be refuted if the censored
    # runs counted as reaching at 12,000: exactly 1.5)
    opts = SpeedupOptions(
        robots=(1, 2, 5),
        seeds=(1, 2, 3),
        conditions=("homogeneous",),
        targets=(0.7,),
        resamples=200,
    )
    results = {}
    for s in opts.seeds:
        results[(arenas("homogeneous", 1), s)] = _run(1, s, None)
        for n in (2, 5):
            results[(arenas("homogeneous", n), s)] = _run(n, s, 8000)
    rows = {(r.measure, r.robots): r for r in analyse(opts, results)}
    base = rows[("error<=0.7", 1)]
    assert base.reached == 0 and base.time.estimate == math.inf and base.ratio is None
    two, five = rows[("error<=0.7", 2)], rows[("error<=0.7", 5)]
    assert two.ratio is not None and two.ratio.known == "at least"
    assert two.ratio.estimate == 1.5 and two.total == 16_000
    assert two.faster is not None and two.faster.outcome is Outcome.HOLDS
    assert five.linear is not None and five.linear.outcome is Outcome.NOT_SIGNIFICANT
    assert verdict(two.faster, "speed-up") == "speed-up holds"
    assert verdict(five.linear, "linear speed-up").startswith("not significant at n = 3")


def test_dfrl_speedup_tiny_end_to_end(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "study"
    args = [
        "speedup",
        "--robots",
        "1",
        "2",
        "--n-seeds",
        "3",
        "--iterations",
        "200",
        "--budget",
        "1=200",
        "--share-every",
        "100",
        "--grid",
        "100",
        "--score-every",
        "200",
        "--eval-steps",
        "50",
        "--targets",
        "0.999",
        "0.2",
        "--resamples",
        "200",
        "--jobs",
        "1",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "### homogeneous" in text and "### heterogeneous" in text
    assert "| error<=0.2 | 1 | 1xr1 | 0/3 | > budget" in text  # censored, said so
    assert "| error<=0.999 | 2 | 1xr1+1xr2 | 3/3 | 100 [100, 100]" in text
    for name in ("speedup.md", "speedup.json", "tidy.csv", "provenance.json", "speedup_runs.jsonl"):
        assert (out / name).is_file(), name
    data = json.loads((out / "speedup.json").read_text())
    censored = [r for r in data["rows"] if r["measure"] == "error<=0.2"]
    assert censored and all(r["reached"] == 0 and r["time"]["estimate"] == "inf" for r in censored)
    assert {r["ratio"]["known"] for r in censored if r["ratio"]} == {"unknown"}
    assert all(run["times"]["error<=0.2"] is None for run in data["runs"])
    with open(out / "tidy.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["metric"] for r in rows} == {"relative_error@r1", "score@r1"}
    assert len([r for r in rows if r["metric"] == "score@r1"]) == 12  # one per run
    # N = 1 counts in both conditions: 2 conditions x 2 N x 3 seeds x 2 grid points
    assert len([r for r in rows if r["metric"] == "relative_error@r1"]) == 24
    assert json.loads((out / "provenance.json").read_text())["command"]
    # the same runs analysed again give the same table; other options find none of them
    runs = out / "speedup_runs.jsonl"
    assert len(runs.read_text().splitlines()) == 9
    assert main([*args[:-2], "--from-runs", str(runs)]) == 0
    again = capsys.readouterr().out
    assert again.split("### homogeneous")[1] == text.split("### homogeneous")[1]
    assert main([*args[:-2], "--iterations", "300", "--from-runs", str(runs)]) == 2
    # N = 1 keeps its own budget (--budget 1=200): only the six federations of N = 2 differ
    assert "6 federations these options need are missing" in capsys.readouterr().err
    # --resume reuses all nine: nothing is run or appended
    assert main([*args, "--resume"]) == 0
    assert "[" not in capsys.readouterr().err and len(runs.read_text().splitlines()) == 9
    assert main(["speedup", "--seeds", "5"]) == 2  # ambiguous
    np.testing.assert_equal(len(data["runs"]), 9)
