"""``dfrl paper`` end to end with tiny budgets: real federated runs, the controls, the table
history, evaluations, band figures, the questions' files and a report (slow)."""

import csv
import json

import pytest

from dfrl.experiments.science.questions.evaluations import read_evaluations
from dfrl.experiments.science.reproduce import PaperOptions, rejudge, reproduce_paper

FEDERATED = [
    "qlearning/average",
    "qlearning/max",
    "qlearning/visit_average",
    "sarsa/average",
    "sarsa/max",
]
CONDITIONS = FEDERATED + [
    "control/qlearning/average",
    "control/sarsa/average",
    "standalone/qlearning",
    "control/standalone/qlearning",
    "standalone/sarsa",
    "control/standalone/sarsa",
    "untrained",
    "reference/zero_table",
]


@pytest.mark.slow
def test_tiny_paper(tmp_path):
    opts = PaperOptions(
        seeds=2, iterations=400, respite=200, points=2, eval_steps=100, episode_steps=50
    )
    rep = reproduce_paper(tmp_path, opts, progress=None)
    assert rep.ok
    assert sorted(rep.runs) == sorted(CONDITIONS)
    assert all(len(v) == 2 for v in rep.runs.values())
    assert sorted(rep.runs["control/standalone/qlearning"][0].arenas) == [
        "r1",
        "r2",
        "r3",
        "r4",
        "r5",
    ]
    hist = sorted(
        p.name
        for p in (tmp_path / "seed1" / "paper_qlearning_average" / "tables" / "history").glob(
            "r1_*.npy"
        )
    )
    assert hist == ["r1_it200.npy", "r1_it400.npy"]
    for run in (
        "control_sarsa_average",
        "paper_qlearning_visit_average",
        "untrained",
        "zero_table",
    ):
        ev = (tmp_path / "seed2" / run / "evaluations.csv").read_text()
        assert ev.startswith("robot,iteration,arena,role") and ",h2,held_out," in ev
    # the study's evaluations: every condition, both seeds, own and held-out rows
    evals = read_evaluations(tmp_path / "evaluations.csv")
    assert {e.run for e in evals} == set(CONDITIONS)
    assert {(e.seed, e.role) for e in evals} == {
        (1, "own"),
        (1, "held_out"),
        (2, "own"),
        (2, "held_out"),
    }
    assert {e.robot_arena for e in evals if e.run == "qlearning/average"} == {
        "r1",
        "r2",
        "r3",
        "r4",
        "r5",
    }
    # 2 seeds: every row cannot be judged; the questions and checks are all there
    text = rep.report.read_text()
    for head in ("### Checks", "### L. Do the robots learn?", "### F.", "### T.", "### M."):
        assert head in text
    assert "Seeds 1, 2 (2); five robots in R1..R5, 400 iterations each" in text
    with open(tmp_path / "questions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["question"] for r in rows} == {"C", "L", "F", "T", "M"}
    assert len([r for r in rows if r["question"] == "L"]) == 8
    assert all(r["verdict"].startswith("cannot") for r in rows)
    # --from gives the same numbers from the evaluations alone
    ans, path = rejudge(tmp_path, out=tmp_path / "again")
    with open(tmp_path / "again" / "questions.csv", newline="") as fh:
        assert list(csv.DictReader(fh)) == rows
    assert path.name == "questions.md"
    # provenance: the study's folder and every federated run's; summary.md names the commit
    assert "Produced by dfrl" in text
    made_by = json.loads((tmp_path / "provenance.json").read_text())
    assert made_by["swipl"] and made_by["pybullet"]
    run_dir = tmp_path / "seed1" / "paper_qlearning_average"
    assert json.loads((run_dir / "provenance.json").read_text())["dfrl"] == made_by["dfrl"]
    assert "- produced by dfrl" in (run_dir / "summary.md").read_text()
    # the tidy table: every run kind, curves and evaluations
    with open(tmp_path / "tidy.csv", newline="") as fh:
        tidy = list(csv.DictReader(fh))
    assert list(tidy[0]) == ["run", "seed", "condition", "robot", "iteration", "metric", "value"]
    assert {r["condition"] for r in tidy} == {
        "federated",
        "standalone",
        "control federated",
        "control standalone",
        "untrained",
        "reference zero table",
    }
    assert {"q_sum", "score@h1"} <= {r["metric"] for r in tidy}
    assert max(int(r["iteration"]) for r in tidy) == 400
