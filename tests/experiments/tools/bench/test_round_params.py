"""``dfrl bench round --learner dqn|linear``: robots hold a network's parameter vector, the agent
carries parameters (FedAvg weighted by samples); real processes, tiny budget."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.config_rules import ConfigError
from dfrl.experiments.processes import find_swipl
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.tools.bench.round import bench, bench_layout, bench_samples
from dfrl.pybridge import StaticParams
from dfrl.pybridge.providers import layout_size

needs_swipl = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


@needs_swipl
def test_params_round_leaves_every_robot_the_samples_weighted_average(tmp_path: Path) -> None:
    # Prepare: what each of the 3 robots starts with (its seed is its index)
    layout = bench_layout("dqn")
    weights = np.array([bench_samples(i) for i in range(3)], dtype=np.float64)
    starts = [StaticParams(layout, seed=i, samples=int(weights[i])).params for i in range(3)]
    fedavg = sum(w * v for w, v in zip(weights, starts)) / weights.sum()
    # Execute
    r = bench(robots=3, rounds=2, warmup=1, hop_hops=2, learner="dqn", out=tmp_path)
    # Assert: the payload is the network's vector, every robot the same after every round
    floats = layout_size(layout)
    assert r["learner"] == "dqn" and r["floats"] == floats and r["payload_bytes"] == 8 * floats
    assert "entries" not in r and r["hop_floats"] == floats
    assert r["all_equal_rounds"] == r["total_rounds"] == 3, r
    assert r["rounds"] == 2 and r["hops"] == 4 and 0 < r["median_ms"] < 5000
    assert r["bytes_carried"] > 8 * floats and 0 < r["hop_median_ms"] < 5000
    assert r["samples"] == [1000, 2000, 3000] and r["log_problems"] == []
    held = [np.load(tmp_path / "params" / f"r{i + 1}.npy") for i in range(3)]
    for vec in held:
        assert vec.shape == (floats,)
        np.testing.assert_allclose(vec, fedavg, rtol=0, atol=1e-9)
    # control: the unweighted mean (or a start) is far from what they hold
    assert np.abs(held[0] - np.mean(starts, axis=0)).max() > 0.1
    assert np.abs(held[0] - starts[0]).max() > 0.1


def test_bench_layout_is_what_a_real_robot_offers() -> None:
    from dfrl.robots.training import Trainer, TrainerConfig

    for learner in ("dqn", "linear"):
        trainer = Trainer(TrainerConfig(algo=learner))
        try:
            assert bench_layout(learner) == trainer.param_layout
            assert layout_size(bench_layout(learner)) == trainer.params.size
        finally:
            trainer.close()
    assert layout_size(bench_layout("dqn")) != layout_size(bench_layout("linear"))


def test_a_bench_robot_has_a_table_or_params_not_both() -> None:
    base = {"robot": "r1", "out_dir": "x", "algo": "dqn"}
    with pytest.raises(ConfigError) as info:
        RobotConfig.from_dict({**base, "bench_table": [10, 4], "bench_params": {"samples": 5}})
    assert info.value.problems == [
        "bench_params: a benchmark robot holds a bench table or bench params, not both "
        "(drop bench_table or bench_params)"
    ]
    with pytest.raises(ConfigError) as info:
        RobotConfig.from_dict({**base, "algo": "qlearning", "bench_params": {"samples": -1}})
    assert info.value.problems == [
        "bench_params: expected {\"samples\": N}, N an integer >= 0, got {'samples': -1}",
        "bench_params: algo 'qlearning' is a tabular learner, it has no network; bench params "
        "need a function learner (linear, dqn)",
    ]
    # controls: either one alone is accepted
    assert RobotConfig.from_dict({**base, "bench_params": {"samples": 5}}).bench_params == {
        "samples": 5
    }
    assert RobotConfig.from_dict({**base, "bench_table": [10, 4]}).bench_params is None


def test_round_command_refuses_a_table_size_for_a_network(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from dfrl.experiments.cli import main

    assert main(["bench", "round", "--learner", "dqn", "--entries", "200", "--json"]) == 2
    err = capsys.readouterr().err
    assert "--entries and --actions size a table" in err
    with pytest.raises(SystemExit):
        main(["bench", "round", "--learner", "tabular"])
