"""A function learner's (dqn, linear) checkpoint, resume and final save in the robot host:
the parameter vector instead of a table, written atomically; a real :class:`Trainer`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.robot_host.checkpoint import (
    checkpoint_of,
    load_checkpoint,
    restore_trainer,
    save_checkpoint,
    save_learnt_atomically,
)
from dfrl.robots.tables import load_params
from dfrl.robots.training import Trainer, TrainerConfig

_SMALL_DQN = {"learning_starts": 16, "batch_size": 8, "hidden": [8]}


def _dqn(seed: int) -> TrainerConfig:
    base = TrainerConfig(seed=seed, algo="dqn", iterations=40).to_dict()
    base["dqn"].update(_SMALL_DQN)
    return TrainerConfig.from_dict(base)


def test_dqn_checkpoint_round_trip_and_resume(tmp_path: Path) -> None:
    # Prepare: a dqn trainer that has learnt for 40 steps (gradient steps from the 16th)
    with Trainer(_dqn(3)) as trainer:
        for _ in range(40):
            trainer.step()
        cp = checkpoint_of(trainer, shares=2)
        learnt, t = trainer.params, trainer.learner.t
        # Execute: write, read back, restore into a fresh trainer of another seed
        save_checkpoint(tmp_path, "r1", cp, meta={"iterations": 40})
        back = load_checkpoint(tmp_path, "r1")
    with Trainer(_dqn(4)) as fresh:
        assert not np.array_equal(fresh.params, learnt)
        restore_trainer(fresh, back)
        # Assert: the parameters (online and target network), clock and counters are back
        assert np.array_equal(fresh.params, learnt)
        assert [
            np.array_equal(a, b) for a, b in zip(fresh.learner.target, fresh.learner.online)
        ] == [True] * 4
        assert (fresh.learner.t, fresh.iteration) == (t, 40) and fresh.samples == t
        assert fresh.cumulative_reward == cp.cumulative_reward
        fresh.step()  # and it learns on from there
    assert back.q is None and back.visits is None and back.shares == 2
    assert np.array_equal(back.learnt, learnt)
    side = (tmp_path / "r1.json").read_text()
    assert '"params_sha256"' in side and "q_sha256" not in side


def test_a_checkpoint_of_the_other_kind_is_refused(tmp_path: Path) -> None:
    with (
        Trainer(TrainerConfig(seed=1, algo="linear")) as linear,
        Trainer(TrainerConfig(seed=1)) as tabular,
    ):
        with pytest.raises(ValueError, match="holds a Q-table"):
            restore_trainer(linear, checkpoint_of(tabular, 0))
        with pytest.raises(ValueError, match="holds parameters"):
            restore_trainer(tabular, checkpoint_of(linear, 0))


def test_final_params_saved_atomically(tmp_path: Path) -> None:
    with Trainer(TrainerConfig(seed=2, algo="linear")) as trainer:
        for _ in range(10):
            trainer.step()
        (tmp_path / "params").mkdir()
        (tmp_path / "params" / "r1.npy").write_bytes(b"\x93NUMPY torn")  # an older torn one
        npy = save_learnt_atomically(trainer, tmp_path, "r1")
        assert npy == tmp_path / "params" / "r1.npy"
        assert sorted(p.name for p in (tmp_path / "params").iterdir()) == ["r1.json", "r1.npy"]
        loaded = load_params(npy)
        assert np.array_equal(loaded.params, trainer.params)
        assert loaded.meta.algo == "linear" and loaded.meta.iterations == 10
    assert not (tmp_path / "tables").exists()
