"""Learner maths on hand-computed values, the registry, schedules, table files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dfrl.robots.learners import (
    LEARNERS,
    EpsilonSchedule,
    LearnerParams,
    QLearning,
    Sarsa,
    epsilon_greedy,
    greedy_action,
    make_learner,
    q_learning_target,
    sarsa_target,
    td_update,
    validate_table,
)
from dfrl.robots.tables import TableMeta, load_params, load_table, save_table


def test_registry_has_the_tabular_and_the_function_learners() -> None:
    from dfrl.robots.dqn import DQN
    from dfrl.robots.learners import is_tabular, learner_kind
    from dfrl.robots.linear import LinearQ

    assert LEARNERS == {"qlearning": QLearning, "sarsa": Sarsa, "linear": LinearQ, "dqn": DQN}
    assert [learner_kind(n) for n in ("qlearning", "sarsa", "linear", "dqn")] == [
        "tabular",
        "tabular",
        "function",
        "function",
    ]
    assert is_tabular("sarsa") and not is_tabular("dqn")
    with pytest.raises(KeyError, match="built in: .*plug-ins"):
        make_learner("ppo", 2, 2, LearnerParams(), np.random.default_rng(0))
    with pytest.raises(TypeError, match="no options"):
        make_learner("qlearning", 2, 2, LearnerParams(), np.random.default_rng(0), config=None)


def test_targets_and_update_by_hand() -> None:
    row = np.array([1.0, 3.0, -2.0])
    assert q_learning_target(0.5, row, 0.9, False) == pytest.approx(0.5 + 0.9 * 3.0)
    assert q_learning_target(-10.0, row, 0.9, True) == -10.0
    assert sarsa_target(0.5, -2.0, 0.9, False) == pytest.approx(0.5 - 1.8)
    assert sarsa_target(1.0, 5.0, 0.9, True) == 1.0
    assert td_update(2.0, 4.0, 0.25) == pytest.approx(2.5)


def test_qlearning_and_sarsa_one_step_by_hand() -> None:
    params = LearnerParams(alpha=0.5, gamma=0.5, epsilon=EpsilonSchedule("constant", 0.0, 0.0, 1))
    for cls, expected in ((QLearning, 0.5 * (1.0 + 0.5 * 4.0)), (Sarsa, 0.5 * (1.0 + 0.5 * 4.0))):
        learner = cls(2, 2, params, np.random.default_rng(0))
        learner.q[1] = [4.0, -1.0]
        nxt = learner.learn(0, 1, 1.0, 1, False)
        assert nxt == 0  # greedy in state 1
        assert learner.q[0, 1] == pytest.approx(expected)
        assert learner.visits.tolist() == [[0, 1], [0, 0]]
    # SARSA bootstraps on the action it actually picks: force exploration of action 1
    sarsa = Sarsa(
        2,
        2,
        LearnerParams(alpha=1.0, gamma=0.5, epsilon=EpsilonSchedule("constant", 1.0, 1.0, 1)),
        np.random.default_rng(3),
    )
    sarsa.q[1] = [4.0, -1.0]
    a2 = sarsa.learn(0, 0, 1.0, 1, False)
    assert sarsa.q[0, 0] == pytest.approx(1.0 + 0.5 * sarsa.q[1, a2])


def test_greedy_ties_and_epsilon() -> None:
    rng = np.random.default_rng(0)
    assert greedy_action(np.array([0.0, 2.0, 1.0])) == 1
    picks = {greedy_action(np.array([1.0, 1.0, 0.0]), rng) for _ in range(50)}
    assert picks == {0, 1}
    assert all(epsilon_greedy(np.array([0.0, 5.0]), 0.0, rng) == 1 for _ in range(20))
    explored = [epsilon_greedy(np.array([0.0, 5.0]), 1.0, rng) for _ in range(200)]
    assert 0 in explored and 1 in explored


def test_epsilon_schedules() -> None:
    lin = EpsilonSchedule("linear", 0.5, 0.1, 100)
    assert [lin.value(t) for t in (0, 50, 100, 1000)] == pytest.approx([0.5, 0.3, 0.1, 0.1])
    exp = EpsilonSchedule("exponential", 1.0, 0.0, 10)
    assert exp.value(10) == pytest.approx(np.exp(-1))
    assert EpsilonSchedule("constant", 0.2, 0.0, 1).value(99) == 0.2
    with pytest.raises(ValueError):
        EpsilonSchedule("linear", 1.5, 0.1, 10)


def test_validate_table() -> None:
    assert validate_table([[1, 2]], (1, 2)).dtype == np.float64
    with pytest.raises(ValueError, match="shape"):
        validate_table(np.zeros((2, 3)), (3, 3))
    bad = np.zeros((2, 2))
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"non-finite entry at \(state, action\) = \(1, 0\)"):
        validate_table(bad, (2, 2))


def test_table_file_round_trip(tmp_path: Path) -> None:
    q = np.arange(12, dtype=float).reshape(4, 3)
    visits = np.arange(12, dtype=np.int64).reshape(4, 3)
    meta = TableMeta(
        algo="sarsa",
        arena="r4",
        seed=3,
        iterations=100,
        actions=["forward", "left", "right"],
        state={"n_states": 4},
    )
    path = save_table(tmp_path / "t", q, meta, visits=visits)
    assert path.name == "t.npy" and (tmp_path / "t.json").exists()
    loaded = load_table(tmp_path / "t.npy")
    np.testing.assert_array_equal(loaded.q, q)
    np.testing.assert_array_equal(loaded.visits, visits)
    assert loaded.meta == meta
    with pytest.raises(ValueError, match="action names"):
        save_table(tmp_path / "u", q, TableMeta("sarsa", "r4", 0, 0, ["a"], {}))


def test_sidecar_names_the_learner_algo_and_one_saying_algorithm_still_loads(
    tmp_path: Path,
) -> None:
    q = np.array([[0.0, 1.0], [2.0, 3.0]])
    save_table(tmp_path / "new", q, TableMeta("sarsa", "r4", 3, 100, ["a", "b"], {}))
    doc = json.loads((tmp_path / "new.json").read_text())
    assert doc["algo"] == "sarsa" and "algorithm" not in doc
    assert doc["format"] == "dfrl-qtable/2"
    # a sidecar written by hand the way dfrl wrote them before (key "algorithm")
    np.save(tmp_path / "old.npy", q)
    (tmp_path / "old.json").write_text(
        json.dumps(
            {
                "format": "dfrl-qtable/1",
                "shape": [2, 2],
                "dtype": "float64",
                "algorithm": "qlearning",
                "arena": "r1",
                "seed": 7,
                "iterations": 50,
                "actions": ["a", "b"],
                "state": {"n_states": 2},
                "extra": {},
            }
        )
    )
    old = load_table(tmp_path / "old.npy")
    assert old.meta == TableMeta("qlearning", "r1", 7, 50, ["a", "b"], {"n_states": 2})
    np.testing.assert_array_equal(old.q, q)
    # a format this dfrl does not know is refused, naming the file and the formats it reads
    doc = json.loads((tmp_path / "old.json").read_text())
    (tmp_path / "old.json").write_text(json.dumps({**doc, "format": "dfrl-qtable/9"}))
    with pytest.raises(ValueError, match="old.json: unknown table format 'dfrl-qtable/9'"):
        load_table(tmp_path / "old.npy")


def test_params_sidecar_saying_algorithm_still_loads(tmp_path: Path) -> None:
    np.save(tmp_path / "old.npy", np.array([0.5, -1.0, 2.0]))
    (tmp_path / "old.json").write_text(
        json.dumps(
            {
                "format": "dfrl-params/1",
                "size": 3,
                "dtype": "float64",
                "algorithm": "linear",
                "arena": "r2",
                "seed": 1,
                "iterations": 10,
                "actions": ["a"],
                "layout": [["w", [1, 3]]],
                "model": {"alpha": 0.1},
                "extra": {},
            }
        )
    )
    meta = load_params(tmp_path / "old.npy").meta
    assert (meta.algo, meta.arena, meta.layout, meta.model) == (
        "linear",
        "r2",
        [("w", (1, 3))],
        {"alpha": 0.1},
    )
