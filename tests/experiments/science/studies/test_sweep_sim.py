"""``dfrl sweep --sim``: the batched sweep trains a setting's seeds in one batch with the
snapshots train() keeps, is the same in any batch, records its simulator, and refuses a
learner it cannot run before any training; pybullet still runs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.science.studies.sweep import setting_config, sweep
from dfrl.experiments.science.studies.sweep_batched import (
    snapshot_points,
    sweep_batched,
    train_setting,
)
from dfrl.robots.batched.training import BatchedTrainer
from dfrl.robots.training import TrainerConfig

BASE = TrainerConfig(arena="r4", iterations=400).to_dict()


def test_snapshots_where_train_keeps_them() -> None:
    assert snapshot_points(400) == [100, 200, 300, 400]
    assert snapshot_points(402) == [100, 200, 300, 400, 402]
    assert snapshot_points(3) == [1, 2, 3]
    cfgs = [setting_config(BASE, (), s) for s in (1, 2)]
    snaps, q_sum, visits = train_setting(cfgs, 2)
    assert sorted(snaps) == [300, 400] and q_sum.shape == (2, 400)
    bt = BatchedTrainer(cfgs[1:])
    bt.run(300)
    assert np.array_equal(snaps[300][1], bt.q[0])  # robot 1 as if alone
    rec = bt.run(100, record=True)
    assert np.array_equal(q_sum[1, 300:], rec.q_sum[0]) and np.array_equal(visits[1], bt.visits[0])


def test_a_seed_is_the_same_in_any_batch() -> None:
    both = sweep_batched(BASE, [(), (("learner.alpha", 0.5),)], [1, 2], ("h1",), 150, 2)
    alone = sweep_batched(BASE, [(("learner.alpha", 0.5),)], [2], ("h1",), 150, 2)
    assert alone[0] == both[1][1:]
    assert both[0] != both[1] and both[1][1]["seed"] == 2
    # the base is batched, the second setting cannot be: refused before the base trains
    with pytest.raises(
        ValueError,
        match="setting algo=dqn: robot 0: learner 'dqn' is not batched .*use --sim pybullet",
    ):
        sweep(BASE, {"algo": ["dqn"]}, [1], sim="batched")


@pytest.mark.parametrize("sim", ["batched", "pybullet"])
def test_the_command_records_its_simulator(
    sim: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert (
        main(
            [
                "sweep",
                "--set",
                "learner.alpha=0.5",
                "--iterations",
                "200",
                "--seeds",
                "1",
                "2",
                "--eval-steps",
                "60",
                "--held-out",
                "h1",
                "--jobs",
                "1",
                "--sim",
                sim,
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    assert capsys.readouterr().out.rstrip().endswith(f"Simulator: {sim}.")
    data = json.loads((tmp_path / "sweep.json").read_text())
    assert [d["sim"] for d in data] == [sim, sim] and len(data[1]["runs"]) == 2
    assert (tmp_path / "sweep.md").read_text().rstrip().endswith(f"Simulator: {sim}.")
