"""The shuffled-reward control (``reward_shuffle``): a seeded, deterministic permutation of the
outcomes (reward, end of episode) a run observed, so that what a learner learns from no longer
depends on the state and action; in the real training loop, for every learner."""
import numpy as np
import pytest

from dfrl.experiments.config_rules import check_trainer
from dfrl.robots.reward_shuffle import RewardShuffle
from dfrl.robots.training import Trainer, TrainerConfig

W = 20


def _shuffle(outcomes, seed, capacity=W):
    s = RewardShuffle(capacity, np.random.default_rng(seed))
    return [s(r, t) for r, t in outcomes], s.buffer


def test_the_buffer_is_a_seeded_permutation_delayed_by_its_capacity():
    # Prepare: 200 distinct rewards, every 7th step a collision
    seen = [(float(i), i % 7 == 0) for i in range(200)]
    # Execute
    out, left = _shuffle(seen, 5)
    again, _ = _shuffle(seen, 5)
    other, _ = _shuffle(seen, 6)
    # Assert: deterministic with a seed, another seed another pairing
    assert out == again and out != other
    # while filling: draws from what was seen so far
    assert all(out[t] in seen[:t + 1] for t in range(W))
    # once full: what was learnt plus what is left is exactly what was seen (same multiset),
    # and no step learns its own outcome
    assert sorted(out[W:] + left) == sorted(seen)
    assert all(out[t] != seen[t] for t in range(W, len(seen)))
    # the pairing really changes: the learnt reward is far from the observed one on average
    assert np.mean([abs(o[0] - s[0]) for o, s in zip(out[W:], seen[W:])]) > W / 4


def test_the_option_is_checked_and_leaves_ordinary_configurations_unchanged():
    with pytest.raises(ValueError, match="reward_shuffle must be an int >= 0"):
        TrainerConfig(reward_shuffle=-1)
    with pytest.raises(ValueError, match="capacity must be >= 1"):
        RewardShuffle(0, np.random.default_rng(0))
    # off: absent from the JSON (reference names hashed from it stay as they were)
    assert "reward_shuffle" not in TrainerConfig().to_dict()
    assert TrainerConfig().to_dict(full=True)["reward_shuffle"] == 0
    on = TrainerConfig(reward_shuffle=50)
    assert on.to_dict()["reward_shuffle"] == 50 and TrainerConfig.from_dict(on.to_dict()) == on
    # an experiment's trainer section takes it; a misspelling is still refused
    assert check_trainer("trainer", {"reward_shuffle": 1000}) == []
    assert "unknown key" in check_trainer("trainer", {"reward_shufle": 1000})[0]


def _run(algo: str, shuffle: int, steps: int, seed: int = 3):
    seen, learnt = [], []
    with Trainer(TrainerConfig(arena="r1", algo=algo, seed=seed, reward_shuffle=shuffle)) as t:
        for _ in range(steps):
            m = t.step()
            seen.append((m.reward, m.collided))
            learnt.append((t.learned_reward, t.learned_terminal))
        left = list(t.reward_shuffle.buffer) if t.reward_shuffle else []
        return seen, learnt, left, t.params


def test_the_trainer_learns_shuffled_outcomes_deterministically():
    # Execute: real pybullet, R1, seed 3, 400 steps (the robot collides in them)
    seen, learnt, left, params = _run("qlearning", 50, 400)
    seen2, learnt2, _, params2 = _run("qlearning", 50, 400)
    plain_seen, plain_learnt, _, _ = _run("qlearning", 0, 400)
    # Assert: the same seed, the same run
    assert seen == seen2 and learnt == learnt2 and np.array_equal(params, params2)
    # an ordinary run learns what it observes; the control learns the same multiset, re-paired
    assert plain_learnt == plain_seen
    assert sorted(learnt[50:] + left) == sorted(seen)
    assert sum(a == b for a, b in zip(learnt[50:], seen[50:])) < 0.2 * 350
    # the collision penalty no longer follows the collision: at the steps that collided the
    # observed reward is the penalty, the learnt one mostly is not
    hits = [t for t in range(50, 400) if seen[t][1]]
    assert len(hits) >= 3, "R1 seed 3 no longer collides in 400 steps: pick another seed"
    assert all(seen[t][0] < -5 for t in hits)
    assert np.mean([learnt[t][0] for t in hits]) > -5
    assert not all(learnt[t][1] for t in hits)


@pytest.mark.parametrize("algo", ["sarsa", "linear", "dqn"])
def test_every_learner_takes_the_option(algo):
    seen, learnt, left, _ = _run(algo, W, 80, seed=2)
    assert sorted(learnt[W:] + left) == sorted(seen)
    assert learnt[W:] != seen[W:]
