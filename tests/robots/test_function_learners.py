"""The learners over the raw observation in the training loop: the parameter contract with the
federated layer, determinism, greedy evaluation, and that they learn on a small budget."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dfrl.robots.evaluation import PolicyKind, evaluate_policy, greedy_policy
from dfrl.robots.tables import load_params
from dfrl.robots.training import Trainer, TrainerConfig, train

#: A dqn that starts learning early, for short tests.
QUICK_DQN = {"learning_starts": 100, "target_update": 50}


def _config(algo: str, seed: int = 1, **changes: object) -> TrainerConfig:
    cfg = TrainerConfig(arena="r1", algo=algo, seed=seed)
    if algo == "dqn":
        cfg = TrainerConfig.from_dict({**cfg.to_dict(), "dqn": QUICK_DQN})
    return cfg.replace(**changes)


def _run(cfg: TrainerConfig, steps: int) -> tuple[list, np.ndarray]:
    with Trainer(cfg) as t:
        metrics = [t.step() for _ in range(steps)]
        return metrics, t.params


@pytest.mark.parametrize("algo", ["linear", "dqn"])
def test_same_seed_same_params_and_metrics(algo: str) -> None:
    m1, p1 = _run(_config(algo), 250)
    m2, p2 = _run(_config(algo), 250)
    assert m1 == m2
    assert p1.tobytes() == p2.tobytes()
    _, p3 = _run(_config(algo, seed=2), 250)
    assert not np.array_equal(p1, p3)


def test_the_parameter_contract() -> None:
    with Trainer(_config("linear")) as t:
        assert t.learner_kind == "function"
        assert t.param_layout == [("w", (3, 257))]
        for _ in range(200):
            t.step()
        assert t.samples == 200
        p = t.params
        assert p.dtype == np.float64 and p.shape == (771,)
        p[:] = 0.0  # a copy: the learner keeps its own
        assert np.any(t.params != 0.0)
        with pytest.raises(TypeError, match="no.*Q-table|without a Q-table"):
            t.q_table
        with pytest.raises(ValueError):
            t.set_params(np.zeros(770))
        with pytest.raises(ValueError):
            t.set_params(np.full(771, np.nan))
    with Trainer(_config("dqn")) as t:
        layout = t.param_layout
        assert [name for name, _ in layout] == ["w1", "b1", "w2", "b2", "w3", "b3"]
        assert t.params.shape == (sum(int(np.prod(s)) for _, s in layout),)
        vec = np.random.default_rng(0).normal(size=t.params.shape)
        t.set_params(vec)
        assert np.array_equal(t.params, vec)
        assert all(np.array_equal(a, b) for a, b in zip(t.learner.target, t.learner.online))


def test_the_parameter_contract_for_tables() -> None:
    with Trainer(TrainerConfig(arena="r1", seed=1)) as t:
        assert t.learner_kind == "tabular"
        for _ in range(100):
            t.step()
        assert t.param_layout == [("q", (81, 3))]
        assert np.array_equal(t.params, t.q_table.ravel()) and t.samples == 100
        new = np.arange(243, dtype=float)
        t.set_params(new)
        assert np.array_equal(t.q_table, new.reshape(81, 3))
        with pytest.raises(ValueError):
            t.set_params(new[:-1])


@pytest.mark.parametrize("algo", ["linear", "dqn"])
def test_params_round_trip_gives_the_same_greedy_actions(algo: str) -> None:
    _, learnt = _run(_config(algo), 600)
    observations = np.random.default_rng(4).random((200, 8))
    with Trainer(_config(algo, seed=9)) as other:
        other.set_params(learnt)
        assert np.array_equal(other.params, learnt)
        mine = [other.greedy_action(x) for x in observations]
    policy = greedy_policy(_config(algo), learnt)
    assert [policy(x) for x in observations] == mine
    assert len(set(mine)) > 1  # not a constant policy


def test_train_writes_a_parameter_file(tmp_path: Path) -> None:
    res = train(_config("linear").replace(iterations=50), tmp_path, snapshot_every=25)
    assert res.q_table is None and res.visits is None
    assert sorted(res.snapshots) == [25, 50] and np.array_equal(res.snapshots[50], res.params)
    loaded = load_params(tmp_path / "params.npy")
    assert np.array_equal(loaded.params, res.params)
    assert loaded.meta.algo == "linear" and loaded.meta.layout == [("w", (3, 257))]
    assert (
        loaded.meta.model == {"alpha": 0.05, "tilings": 4, "tiles": 8}
        and loaded.meta.iterations == 50
    )
    cfg = json.loads((tmp_path / "config.json").read_text())
    assert TrainerConfig.from_dict(cfg) == _config("linear").replace(iterations=50)
    assert not (tmp_path / "q_table.npy").exists()


def _score(cfg: TrainerConfig, params: np.ndarray | None, seed: int) -> float:
    """progress - 0.05 * collisions per 1,000 steps (the studies' score), 1,000 greedy steps."""
    policy = PolicyKind.GREEDY if params is not None else PolicyKind.RANDOM
    r = evaluate_policy(cfg, policy, 1000, 20_000 + seed, params=params, episode_steps=250)
    return r.progress - 0.05 * r.collisions_per_1000


def _learns(algo: str, seeds: tuple[int, ...], iterations: int) -> None:
    for seed in seeds:
        cfg = _config(algo, seed).replace(iterations=iterations)
        if algo == "dqn":
            cfg = cfg.replace(dqn=TrainerConfig().dqn)  # the documented defaults
        learnt = _score(cfg, train(cfg).params, seed)
        untrained = _score(cfg, train(cfg.replace(iterations=0)).params, seed)
        random = _score(cfg, None, seed)
        assert learnt > untrained + 0.1, (seed, learnt, untrained)
        assert learnt > random + 0.1, (seed, learnt, random)
        assert learnt > 0.6, (seed, learnt)


def test_linear_learns_on_a_small_budget() -> None:
    """8,000 iterations in R1 (about 4 s each), 3 seeds: the greedy policy beats the same
    learner untrained (a control that cannot learn) and a random policy."""
    _learns("linear", (1, 2, 3), 8000)


def test_dqn_learns_on_a_small_budget() -> None:
    """6,000 iterations in R1 (about 10 s each), 2 seeds, default hyper-parameters."""
    _learns("dqn", (1, 2), 6000)


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["linear", "dqn"])
def test_function_learners_learn_across_seeds(algo: str) -> None:
    """The README's budget (8,000 iterations, the demo budget) on the seeds not tested above."""
    _learns(algo, (3, 4, 5) if algo == "dqn" else (4, 5), 8000)
