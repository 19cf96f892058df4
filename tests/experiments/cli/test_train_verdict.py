"""``dfrl train`` ends with a verdict on whether the robot learnt (its greedy policy against
random actions and the untrained learner, real pybullet episodes) and names in its plot what
the curve sums."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dfrl.experiments.cli import main


def _train(out: Path, *flags: str) -> int:
    return main(
        ["train", "--arena", "r1", "--seed", "1", "--out", str(out), "--no-progress", *flags]
    )


def test_train_says_the_robot_learnt(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # linear Q, 4,000 iterations: drives ahead more than random (and collides more: said)
    assert _train(tmp_path, "--algo", "linear", "--iterations", "4000", "--no-plot") == 0
    printed = capsys.readouterr().out.splitlines()
    check = json.loads((tmp_path / "learning_check.json").read_text())
    assert check["learnt"] is True and check["vs_random"]["low"] > 0
    d = check["vs_random"]
    verdict = (
        f"learnt: better than random by {d['difference']:.3f} reward per step "
        f"[{d['low']:.3f}, {d['high']:.3f}]"
    )
    assert check["verdict"].startswith(verdict) and check["verdict"] in printed
    assert "collides more often than random" in check["verdict"]
    assert any(line.startswith("against the untrained learner: ") for line in printed)
    assert any(
        line.startswith("evaluation budget: 3 policies x 6 episodes x 200 steps (3,600 steps, ")
        for line in printed
    ), printed
    rewards = check["policies"]["learnt"]["reward_per_step"]
    assert len(rewards) == 6 and d["difference"] == pytest.approx(
        sum(rewards) / 6 - sum(check["policies"]["random"]["reward_per_step"]) / 6
    )


def test_train_says_when_the_robot_did_not_learn(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # one iteration: nothing learnt; the untrained table (all zeros, ties broken at random
    # from the evaluation's seed) drives exactly as random actions do
    assert _train(tmp_path, "--algo", "qlearning", "--iterations", "1", "--no-plot") == 0
    printed = capsys.readouterr().out.splitlines()
    check = json.loads((tmp_path / "learning_check.json").read_text())
    assert check["learnt"] is False and check["verdict"].startswith("did not learn: ")
    assert check["verdict"] in printed
    policies = check["policies"]
    assert policies["untrained"] == policies["random"]


def test_train_plot_names_what_it_sums(tmp_path: Path) -> None:
    import matplotlib

    matplotlib.rcParams["svg.fonttype"] = "none"  # text as text, to be read back
    try:
        for algo, summed, other in (
            ("linear", "Sum of parameters", "Q-values"),
            ("qlearning", "Sum of Q-values", "parameters"),
        ):
            out = tmp_path / algo
            assert (
                _train(
                    out,
                    "--algo",
                    algo,
                    "--iterations",
                    "50",
                    "--eval-episodes",
                    "0",
                    "--figure-format",
                    "svg",
                )
                == 0
            )
            svg = (out / "learning_curves.svg").read_text()
            assert summed in svg and other not in svg, algo
            assert not (out / "learning_check.json").exists()  # --eval-episodes 0
    finally:
        matplotlib.rcParams["svg.fonttype"] = "path"


def test_train_refuses_an_evaluation_without_an_interval(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _train(tmp_path, "--iterations", "1", "--eval-episodes", "1") == 2
    assert "--eval-episodes: 0 (no verdict) or at least 2" in capsys.readouterr().err
    assert not tmp_path.exists() or not any(tmp_path.iterdir())  # nothing ran
