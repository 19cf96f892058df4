"""``dfrl bench sim`` with a tiny budget: both simulators, with and without learning."""

from __future__ import annotations

import json

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.tools.bench.sim import pybullet_steps


def test_pybullet_steps_fit_the_budget() -> None:
    assert pybullet_steps(1, 5000, 40_000) == 5000
    assert pybullet_steps(64, 5000, 40_000) == 625
    assert pybullet_steps(1024, 5000, 40_000) == 39
    assert pybullet_steps(100_000, 5000, 40_000) == 1  # never zero


def test_bench_sim_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            [
                "bench",
                "sim",
                "--steps",
                "20",
                "--robots",
                "1",
                "3",
                "--warmup",
                "2",
                "--pybullet-budget",
                "30",
                "--pybullet-live",
                "2",
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    points = out["points"]
    # alternating: for each count and learning mode, pybullet then batched
    assert [(p["robots"], p["learning"], p["sim"]) for p in points] == [
        (n, learning, sim)
        for n in (1, 3)
        for learning in (True, False)
        for sim in ("pybullet", "batched")
    ]
    for p in points:
        assert p["steps_per_s_per_core"] > 0 and p["wall_s"] > 0 and p["cpu_s"] >= 0
        assert p["steps_per_cpu_s"] > 0
        assert p["robot_steps"] == p["steps"] * p["robots"]
        assert p["steps_per_s_per_core"] == pytest.approx(p["robot_steps"] / p["wall_s"], rel=0.01)
    pybullet = [p for p in points if p["sim"] == "pybullet"]
    batched = [p for p in points if p["sim"] == "batched"]
    assert [p["steps"] for p in pybullet] == [20, 20, 10, 10]  # 30 robot-steps at most
    assert [p["live"] for p in pybullet] == [1, 1, 2, 2]
    assert all(p["steps"] == 20 and p["compile_s"] >= 0 for p in batched)
    assert out["cores"] == 1 and out["sims"] == ["pybullet", "batched"]
    by_point = {(p["sim"], p["robots"], p["learning"]): p["steps_per_s_per_core"] for p in points}
    assert [(r["robots"], r["learning"]) for r in out["ratios"]] == [
        (1, True),
        (1, False),
        (3, True),
        (3, False),
    ]
    for r in out["ratios"]:
        expected = (
            by_point["batched", r["robots"], r["learning"]]
            / by_point["pybullet", r["robots"], r["learning"]]
        )
        assert r["batched_over_pybullet"] == pytest.approx(expected, rel=0.05, abs=0.1)
    # the older report's fields: pybullet with learning
    assert out["steps_per_s"] > 0 and out["realtime_factor"] == pytest.approx(
        out["steps_per_s"] * 0.064, rel=0.01
    )
    assert [r["robots"] for r in out["scaling"]] == [1, 3]


def test_bench_sim_one_simulator_as_text(capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            ["bench", "sim", "--sims", "batched", "--steps", "10", "--robots", "2", "--warmup", "1"]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "steps/s/core" in text and "pybullet:" not in text
    assert text.count("\nbatched ") == 2 and "batched / pybullet" not in text


def test_bench_sim_refuses_a_learner_the_batched_simulator_lacks(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["bench", "sim", "--algo", "dqn", "--steps", "10", "--robots", "1"]) == 2
    assert "learner 'dqn' is not batched" in capsys.readouterr().err
