"""The linear learner: its feature map and one semi-gradient update, by hand."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.robots.features import TileCoding, active_features, feature_vector
from dfrl.robots.learners import EpsilonSchedule, LearnerParams
from dfrl.robots.linear import LinearConfig, LinearQ, linear_q, semi_gradient_update

GREEDY = EpsilonSchedule("constant", 0.0, 0.0, 1)


def test_tile_coding_by_hand() -> None:
    # Prepare: 2 sensors, 2 tilings of 3 tiles (width 0.5; tiling 1 shifted by half a tile)
    coding = TileCoding(tilings=2, tiles=3)
    # Execute / Assert: sensor 0 at 0 -> tile 0 in both tilings (indices 1 and 1 + 3);
    # sensor 1 at 0.8 -> floor(1.6) = 1 and floor(2.1) = 2 (indices 1 + 6 + 1, 1 + 9 + 2)
    assert coding.n_features(2) == 13 and coding.n_active(2) == 5
    assert active_features(np.array([0.0, 0.8]), coding).tolist() == [0, 1, 4, 8, 12]
    # 1.0 is the last tile in every tiling; values outside [0, 1] are clipped
    assert active_features(np.array([1.0, 1.7]), coding).tolist() == [0, 3, 6, 9, 12]
    assert active_features(np.array([-0.2, 0.49]), coding).tolist() == [0, 1, 4, 7, 11]
    phi = feature_vector(np.array([0.0, 0.8]), coding)
    assert phi.sum() == 5 and np.flatnonzero(phi).tolist() == [0, 1, 4, 8, 12]


def test_tile_coding_and_config_reject_bad_values() -> None:
    with pytest.raises(ValueError):
        TileCoding(tilings=0)
    with pytest.raises(ValueError):
        TileCoding(tiles=1)
    with pytest.raises(ValueError):
        LinearConfig(tiles=1)
    with pytest.raises(ValueError):
        LinearConfig(alpha=0.0)


def test_linear_q_and_update_maths_by_hand() -> None:
    w = np.arange(12, dtype=float).reshape(2, 6)
    assert linear_q(w, np.array([0, 2, 5])).tolist() == [0 + 2 + 5, 6 + 8 + 11]
    # q = 1 + 2 + 3 = 6, target 10, alpha 0.5: each of 3 weights moves by 0.5 / 3 * 4
    new = semi_gradient_update(np.array([1.0, 2.0, 3.0]), 10.0, 0.5)
    assert new == pytest.approx([1 + 2 / 3, 2 + 2 / 3, 3 + 2 / 3])
    assert new.sum() == pytest.approx(6 + 0.5 * (10 - 6))


def test_one_semi_gradient_q_learning_step_by_hand() -> None:
    # Prepare: x = (0, 0.8) has active features {0, 1, 4, 8, 12}, x' = (1, 1) has {0, 3, 6, 9, 12}
    params = LearnerParams(gamma=0.5, epsilon=GREEDY)
    learner = LinearQ(
        2, 2, params, np.random.default_rng(0), LinearConfig(alpha=0.5, tilings=2, tiles=3)
    )
    learner.weights[0, [0, 12]] = 1.0  # Q(x, 0) = 2, Q(x', 0) = 2
    learner.weights[1, 3] = 4.0  # Q(x', 1) = 4
    x, x2 = np.array([0.0, 0.8]), np.array([1.0, 1.0])
    assert learner.q_values(x).tolist() == [2.0, 0.0]
    assert learner.q_values(x2).tolist() == [2.0, 4.0]
    # Execute: reward 1 -> target 1 + 0.5 * 4 = 3, TD error 1, each active weight + 0.5 / 5
    nxt = learner.learn(x, 0, 1.0, x2, False)
    # Assert
    assert learner.weights[0, [0, 1, 4, 8, 12]] == pytest.approx([1.1, 0.1, 0.1, 0.1, 1.1])
    assert learner.q_values(x)[0] == pytest.approx(2.5)  # moved half way to 3
    assert learner.weights[1].tolist() == [0, 0, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    assert nxt == 1 and learner.t == 1  # greedy in x': 4 > 2.2
    # a terminal transition does not bootstrap: target = reward = -10
    before = learner.q_values(x2)[1]
    learner.learn(x2, 1, -10.0, x, True)
    assert learner.q_values(x2)[1] == pytest.approx(before + 0.5 * (-10.0 - before))


def test_initial_q_and_params() -> None:
    learner = LinearQ(8, 3, LearnerParams(initial_q=2.0), np.random.default_rng(0))
    assert learner.q_values(np.full(8, 0.3)).tolist() == [2.0, 2.0, 2.0]
    assert learner.param_layout == [("w", (3, 257))]
    vec = np.arange(3 * 257, dtype=float)
    learner.set_params(vec)
    assert learner.weights[1, 0] == 257.0
    got = learner.get_params()
    assert np.array_equal(got, vec)
    got[0] = 99.0  # a copy: the learner is unchanged
    assert learner.weights[0, 0] == 0.0
    with pytest.raises(ValueError, match="does not fit"):
        learner.set_params(vec[:-1])
    bad = vec.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        learner.set_params(bad)
    assert learner.weights[0, 5] == 5.0  # a refused vector changes nothing
