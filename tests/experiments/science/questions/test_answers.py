"""The questions judged from evaluations: controls checked before L, Holm within each
question, located errors on bad rows, and ``dfrl paper --from`` re-judging a folder."""

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.science.questions.answers import answer
from dfrl.experiments.science.questions.evaluations import (
    COLUMNS,
    Evaluation,
    EvaluationsError,
    read_evaluations,
    write_evaluations,
)

ARENAS = ("r1", "r2", "r3")


def _study(levels: dict[str, float], seeds=(1, 2, 3, 4, 5), spread=0.05, rng_seed=0):
    """Evaluations of conditions whose own and held-out scores are level + noise."""
    rng = np.random.default_rng(rng_seed)
    out = []
    for run, level in levels.items():
        for s in seeds:
            for a in ARENAS:
                for arena, role in ((a, "own"), ("h1", "held_out")):
                    score = level + rng.normal(0, spread)
                    out.append(Evaluation(run, s, a, a, 1000, arena, role, score, 5.0, score))
    return out


LEARNT = {
    "untrained": 0.0,
    "standalone/qlearning": 0.8,
    "control/standalone/qlearning": 0.0,
    "qlearning/average": 0.85,
    "control/qlearning/average": 0.0,
    "qlearning/max": 0.8,
}


def test_a_learner_against_controls_that_learn_nothing_holds():
    ans = answer(_study(LEARNT))
    assert all(c.passes for c in ans.checks) and len(ans.checks) == 2
    assert ans.learns() == {"standalone/qlearning": "holds", "qlearning/average": "holds"}


def test_non_learners_fed_as_real_runs_hold_nothing():
    levels = dict(LEARNT, **{"standalone/qlearning": 0.0, "qlearning/average": 0.01})
    ans = answer(_study(levels, rng_seed=3))
    assert all(v != "holds" for v in ans.learns().values())
    assert all(a.judged.outcome.value != "holds" for a in ans.questions["L"])


def test_a_control_that_learns_vetoes_its_condition():
    ans = answer(_study(dict(LEARNT, **{"control/qlearning/average": 0.6})))
    bad = next(c for c in ans.checks if c.row.a == "control/qlearning/average")
    assert not bad.passes and "FAILS" in bad.words()
    assert ans.learns()["qlearning/average"].startswith("cannot judge (its control")
    assert ans.learns()["standalone/qlearning"] == "holds"


def test_without_a_control_l_cannot_be_judged_but_f_t_m_are():
    levels = {k: v for k, v in LEARNT.items() if not k.startswith("control/")}
    ans = answer(_study(levels))
    assert all(v.startswith("cannot judge (no learning control") for v in ans.learns().values())
    assert [a.row.label for a in ans.questions["F"]] == [
        "qlearning/average - standalone/qlearning",
        "qlearning/max - standalone/qlearning",
    ]
    assert [a.row.role for a in ans.questions["T"]] == ["held_out", "held_out"]
    assert [a.row.label for a in ans.questions["M"]] == ["qlearning: average - max"]


def test_conditions_are_paired_on_the_arenas_and_seeds_both_have():
    ev = _study(LEARNT)
    ev = [e for e in ev if not (e.run == "qlearning/average" and (e.seed == 5 or e.robot == "r3"))]
    ans = answer(ev)
    f = next(a for a in ans.questions["F"] if a.row.a == "qlearning/average")
    assert f.judged.contrast.seeds == (1, 2, 3, 4)


def test_bad_rows_are_located(tmp_path: Path):
    path = tmp_path / "evaluations.csv"
    write_evaluations(path, _study({"untrained": 0.0}, seeds=(1,)))
    assert len(read_evaluations(path)) == 6
    lines = path.read_text().splitlines()
    lines[3] = (
        lines[3].replace(",own,", ",sideways,")
        if ",own," in lines[3]
        else lines[3].replace(",held_out,", ",sideways,")
    )
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(EvaluationsError, match=r"evaluations.csv:4: role must be one of"):
        read_evaluations(path)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        w.writerow(["untrained", "1", "r1", "r1", "10", "r1", "own", "nan", "0", "0"])
    with pytest.raises(EvaluationsError, match=r":2: score is not finite"):
        read_evaluations(path)
    path.write_text("run,seed\nx,1\n")
    with pytest.raises(EvaluationsError, match=r":1: missing column\(s\) robot"):
        read_evaluations(path)


def _dfrl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "dfrl", *args], capture_output=True, text=True, timeout=120
    )


def test_paper_from_rejudges_a_folder_and_runs_nothing(tmp_path: Path):
    write_evaluations(tmp_path / "evaluations.csv", _study(LEARNT))
    r = _dfrl("paper", "--from", str(tmp_path), "--delta", "F=0.2", "--resamples", "200")
    assert r.returncode == 0, r.stderr
    assert "L  standalone/qlearning: holds" in r.stdout
    text = (tmp_path / "questions.md").read_text()
    assert "F 0.2" in text and "### L. Do the robots learn?" in text
    with open(tmp_path / "questions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    f = [x for x in rows if x["question"] == "F"]
    assert f and all(float(x["delta"]) == 0.2 for x in f)
    by_seed = (tmp_path / "contrasts_by_seed.csv").read_text().splitlines()
    assert by_seed[0] == "question,contrast,seed,a,b,difference" and len(by_seed) > 20
    assert not list(tmp_path.glob("seed*"))  # nothing ran


def test_paper_from_refuses_bad_input_with_its_location(tmp_path: Path):
    (tmp_path / "evaluations.csv").write_text(",".join(COLUMNS) + "\nx,one,r1,r1,1,r1,own,0,0,0\n")
    r = _dfrl("paper", "--from", str(tmp_path))
    assert r.returncode == 2 and "evaluations.csv:2: seed must be an integer" in r.stderr
    r = _dfrl("paper", "--from", str(tmp_path), "--delta", "Q=1")
    assert r.returncode == 2 and "--delta 'Q=1'" in r.stderr
    r = _dfrl("paper", "--from", str(tmp_path), "--resamples", "20")
    assert r.returncode == 2 and "--resamples 20: at least 100" in r.stderr
    (tmp_path / "evaluations.csv").write_text(",".join(COLUMNS) + "\n")
    r = _dfrl("paper", "--from", str(tmp_path))
    assert r.returncode == 2 and "no evaluation rows: nothing to judge" in r.stderr
    r = _dfrl("paper", "--from", str(tmp_path / "missing"))
    assert r.returncode == 2 and "No such file" in r.stderr
