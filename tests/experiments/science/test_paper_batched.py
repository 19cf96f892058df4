"""``dfrl paper --sim batched``: every condition of every seed in one batch, judged by the
questions (real batched simulator runs at a tiny budget)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from dfrl.experiments.science.questions.evaluations import read_evaluations


def _paper(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "dfrl.experiments", "paper", *args],
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_every_condition_is_evaluated_judged_and_the_same_with_the_same_seed(
    tmp_path: Path,
) -> None:
    args = (
        "--sim",
        "batched",
        "--n-seeds",
        "3",
        "--iterations",
        "600",
        "--respite",
        "200",
        "--eval-steps",
        "100",
        "--resamples",
        "200",
    )
    out = tmp_path / "paper"
    r = _paper(*args, "--out", str(out))
    assert r.returncode == 0, r.stderr
    evals = read_evaluations(out / "evaluations.csv")
    runs = {e.run for e in evals}
    assert {
        "qlearning/average",
        "qlearning/max",
        "qlearning/visit_average",
        "sarsa/average",
        "sarsa/max",
        "standalone/qlearning",
        "standalone/sarsa",
        "control/qlearning/average",
        "control/standalone/sarsa",
        "untrained",
        "reference/zero_table",
    } <= runs
    assert {e.seed for e in evals} == {1, 2, 3}
    fed = [e for e in evals if e.run == "qlearning/average" and e.seed == 1]
    assert {e.robot_arena for e in fed if e.role == "own"} == {"r1", "r2", "r3", "r4", "r5"}
    assert {e.arena for e in fed if e.role == "held_out"} == {"h1", "h2"}
    assert {e.iteration for e in evals} == {600}
    assert json.loads((out / "options.json").read_text())["sim"] == "batched"
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "batched simulator" in report and "### F." in report
    assert (out / "questions.csv").is_file()
    # the same seeds again: the same evaluations, byte for byte
    again = tmp_path / "again"
    assert _paper(*args, "--out", str(again)).returncode == 0
    assert (out / "evaluations.csv").read_bytes() == (again / "evaluations.csv").read_bytes()


def test_what_the_batch_cannot_run_is_refused(tmp_path: Path) -> None:
    r = _paper("--sim", "batched", "--driver", "--n-seeds", "1", "--out", str(tmp_path))
    assert r.returncode == 2 and "no --driver" in r.stderr


def test_f_and_t_are_confirmed_on_pybullet(tmp_path: Path) -> None:
    out = tmp_path / "paper"
    r = _paper(
        "--sim",
        "batched",
        "--n-seeds",
        "2",
        "--iterations",
        "200",
        "--respite",
        "100",
        "--eval-steps",
        "30",
        "--resamples",
        "200",
        "--no-control",
        "--confirm-seeds",
        "1",
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    found = json.loads((out / "confirmation.json").read_text())
    assert found["seeds"] == [1]
    names = [c["contrast"] for c in found["contrasts"]]
    assert len(names) == 10 and all(n.startswith(("F: ", "T: ")) for n in names)
    assert all(c["pybullet"]["n"] == 1 and c["batched"]["n"] == 2 for c in found["contrasts"])
    assert (out / "confirm_pybullet" / "evaluations.csv").is_file()
    assert "## Confirmation in pybullet" in (out / "report.md").read_text(encoding="utf-8")
    r = _paper("--confirm-seeds", "1", "--n-seeds", "1", "--out", str(tmp_path / "x"))
    assert r.returncode == 2 and "confirms a --sim batched study" in r.stderr
    r = _paper(
        "--sim", "batched", "--confirm-seeds", "3", "--n-seeds", "2", "--out", str(tmp_path / "y")
    )
    assert r.returncode == 2 and "between 0 and the study's 2 seeds" in r.stderr
