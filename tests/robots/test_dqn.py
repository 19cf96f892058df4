"""The dqn learner: targets on a hand-made batch, the replay buffer, the target network."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.robots.dqn import (
    DQN,
    Adam,
    DQNConfig,
    ReplayBuffer,
    dqn_targets,
    huber,
    mlp_forward,
    mlp_layout,
)
from dfrl.robots.learners import EpsilonSchedule, LearnerParams

GREEDY = EpsilonSchedule("constant", 0.0, 0.0, 1)


def test_targets_on_a_hand_made_batch() -> None:
    rewards = np.array([1.0, -10.0, 0.3])
    next_q = np.array(
        [
            [2.0, 5.0, 1.0],  # max 5
            [9.0, 9.0, 9.0],  # terminal: ignored
            [-1.0, -3.0, -2.0],
        ]
    )  # max -1
    terminals = np.array([False, True, False])
    y = dqn_targets(rewards, next_q, terminals, 0.5)
    assert y.tolist() == pytest.approx([1.0 + 2.5, -10.0, 0.3 - 0.5])


def test_huber_by_hand() -> None:
    d = np.array([-3.0, -1.0, 0.5, 2.0])
    assert huber(d, 1.0).tolist() == pytest.approx([2.5, 0.5, 0.125, 1.5])


def test_mlp_layout_and_forward_by_hand() -> None:
    assert mlp_layout(8, (64, 64), 3) == [
        ("w1", (8, 64)),
        ("b1", (64,)),
        ("w2", (64, 64)),
        ("b2", (64,)),
        ("w3", (64, 3)),
        ("b3", (3,)),
    ]
    # 2 -> 2 (ReLU) -> 1: h = relu([1, 2] @ [[1, -1], [1, -1]] + [0, 0]) = relu([3, -3]) = [3, 0]
    w = [
        np.array([[1.0, -1.0], [1.0, -1.0]]),
        np.zeros(2),
        np.array([[2.0], [5.0]]),
        np.array([0.5]),
    ]
    assert mlp_forward(w, np.array([[1.0, 2.0]])).tolist() == [[6.5]]


def test_replay_buffer_keeps_the_newest_and_samples_what_it_holds() -> None:
    buf = ReplayBuffer(3, obs_dim=1)
    with pytest.raises(ValueError, match="empty"):
        buf.sample(2, np.random.default_rng(0))
    for k in range(2):
        buf.add(np.array([k]), k % 2, float(k), np.array([k + 1]), k == 1)
    assert len(buf) == 2 and buf.added == 2
    _, a, r, _, _ = buf.sample(50, np.random.default_rng(0))
    assert set(r.tolist()) == {0.0, 1.0}  # never the empty third slot
    for k in range(2, 5):
        buf.add(np.array([k]), k % 2, float(k), np.array([k + 1]), False)
    assert len(buf) == 3 and buf.added == 5
    assert sorted(buf.rewards.tolist()) == [2.0, 3.0, 4.0]  # 0 and 1 overwritten
    x, a, r, x2, term = buf.sample(100, np.random.default_rng(1))
    assert set(r.tolist()) == {2.0, 3.0, 4.0}
    assert np.array_equal(x[:, 0], r) and np.array_equal(x2[:, 0], r + 1)
    assert np.array_equal(a, r.astype(int) % 2) and not term.any()
    # the same generator state draws the same batch
    assert np.array_equal(
        buf.sample(7, np.random.default_rng(5))[2], buf.sample(7, np.random.default_rng(5))[2]
    )


def test_adam_first_step_moves_each_weight_by_lr_against_its_gradient_sign() -> None:
    a = [np.array([1.0, -2.0])]
    opt = Adam.for_arrays(a, lr=0.1)
    opt.step(a, [np.array([3.0, -0.5])])
    assert a[0] == pytest.approx([0.9, -1.9], abs=1e-6)  # bias-corrected m/sqrt(v) = sign(g)


def _dqn(**cfg: object) -> DQN:
    config = DQNConfig(**{"hidden": (4,), "batch_size": 4, "learning_starts": 2, **cfg})
    return DQN(2, 2, LearnerParams(gamma=0.5, epsilon=GREEDY), np.random.default_rng(3), config)


def test_target_network_is_synced_every_target_update_gradient_steps() -> None:
    learner = _dqn(target_update=3)
    assert all(np.array_equal(t, o) for t, o in zip(learner.target, learner.online))
    x = np.array([0.2, 0.9])
    learner.learn(x, 0, 1.0, x, False)  # 1 transition: no gradient step yet
    assert learner.updates == 0
    for k in range(2):  # gradient steps 1 and 2
        learner.learn(x, k % 2, 1.0, x, False)
    assert learner.updates == 2
    assert not all(np.array_equal(t, o) for t, o in zip(learner.target, learner.online))
    frozen = [t.copy() for t in learner.target]
    learner.learn(x, 1, 1.0, x, False)  # step 3: sync
    assert learner.updates == 3
    assert all(np.array_equal(t, o) for t, o in zip(learner.target, learner.online))
    assert not all(np.array_equal(t, f) for t, f in zip(learner.target, frozen))


def test_a_gradient_step_lowers_the_loss_on_its_batch() -> None:
    learner = _dqn(learning_starts=10**6, lr=1e-2, buffer_size=16)  # no automatic steps
    rng = np.random.default_rng(0)
    for _ in range(16):
        learner.learn(
            rng.random(2), int(rng.integers(2)), float(rng.normal()), rng.random(2), False
        )
    x, a, r, x2 = (
        learner.buffer.obs,
        learner.buffer.actions,
        learner.buffer.rewards,
        learner.buffer.next_obs,
    )
    y = dqn_targets(r, mlp_forward(learner.target, x2), learner.buffer.terminals, 0.5)

    def loss() -> float:
        return float(huber(mlp_forward(learner.online, x)[np.arange(16), a] - y, 1.0).mean())

    before = loss()
    grads = learner._grad(learner.online, x, a, y)
    learner.optimizer.step(learner.online, grads)
    assert loss() < before


def test_set_params_sets_online_and_target() -> None:
    learner = _dqn()
    n = sum(int(np.prod(s)) for _, s in learner.param_layout)
    assert learner.get_params().shape == (n,) == (2 * 4 + 4 + 4 * 2 + 2,)
    vec = np.linspace(-1.0, 1.0, n)
    learner.set_params(vec)
    assert np.array_equal(learner.get_params(), vec)
    assert np.array_equal(learner.target[0].ravel(), vec[:8])
    assert np.array_equal(learner.target[-1], vec[-2:])
    with pytest.raises(ValueError):
        learner.set_params(np.append(vec, 0.0))
    with pytest.raises(ValueError):
        learner.set_params(np.where(np.arange(n) == 3, np.inf, vec))


def test_config_is_checked() -> None:
    with pytest.raises(ValueError):
        DQNConfig(hidden=(0,))
    with pytest.raises(ValueError):
        DQNConfig(lr=0.0)
    with pytest.raises(ValueError):
        DQNConfig(target_update=0)
    assert DQNConfig(hidden=[32]).hidden == (32,)
