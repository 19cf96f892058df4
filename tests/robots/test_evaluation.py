"""The evaluation measure tells driving from spinning (issue 10)."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.robots.evaluation import PolicyKind, evaluate_policy
from dfrl.robots.training import TrainerConfig

FORWARD, LEFT, RIGHT = 0, 1, 2  # ActionSet.BASIC


def spin(obs: np.ndarray) -> int:
    """Turn on the spot forever: never collides, goes nowhere."""
    return LEFT


def avoider(obs: np.ndarray) -> int:
    """Hand-made obstacle avoidance: ahead unless a front sensor sees something, then turn
    away from the nearer side (sensors 0-2 are on the right, 5-7 on the left)."""
    right, left = obs[[0, 1, 2]].max(), obs[[5, 6, 7]].max()
    front = max(obs[0], obs[7], obs[1], obs[6])
    if front < 0.05:
        return FORWARD
    return LEFT if right >= left else RIGHT


@pytest.mark.parametrize("arena", ["r1", "r4"])
def test_spinning_scores_low_and_a_hand_made_avoider_scores_high(arena: str) -> None:
    cfg = TrainerConfig(arena=arena)
    spun = evaluate_policy(cfg, spin, 1500, seed=3, episode_steps=300)
    good = evaluate_policy(cfg, avoider, 1500, seed=3, episode_steps=300)
    rand = evaluate_policy(cfg, PolicyKind.RANDOM, 1500, seed=3, episode_steps=300)
    # spinning: no collisions, yet no progress and almost no floor covered
    assert spun.collisions == 0
    assert abs(spun.progress) < 0.05 and spun.coverage < 0.05
    # the avoider drives: most of its steps are ahead at speed, it covers far more floor
    # and collides less than random actions do
    assert good.progress > 0.5, good
    assert good.coverage > 5 * spun.coverage and good.coverage > 0.15, good
    assert good.collisions_per_1000 < rand.collisions_per_1000, (good, rand)
    assert good.episodes == spun.episodes == 5


def test_same_seed_same_measure() -> None:
    cfg = TrainerConfig(arena="r2")
    a = evaluate_policy(cfg, PolicyKind.RANDOM, 400, seed=11, episode_steps=100)
    b = evaluate_policy(cfg, PolicyKind.RANDOM, 400, seed=11, episode_steps=100)
    c = evaluate_policy(cfg, PolicyKind.RANDOM, 400, seed=12, episode_steps=100)
    assert a == b and a != c


def test_snapshots_are_evaluated_in_own_and_held_out_arenas() -> None:
    from dfrl.robots.evaluation import EVAL_FIELDS, evaluate_snapshots
    from dfrl.robots.training import train

    cfg = TrainerConfig(arena="r4", iterations=600, seed=2)
    res = train(cfg, snapshot_every=200)
    assert sorted(res.snapshots) == [200, 400, 600]
    assert np.array_equal(res.snapshots[600], res.q_table)
    assert not np.array_equal(res.snapshots[200], res.snapshots[600])
    rows = evaluate_snapshots(
        cfg, res.snapshots, ["r4", "h1"], steps=200, seed=5, episode_steps=100
    )
    assert [(r["iteration"], r["arena"]) for r in rows] == [
        (200, "r4"),
        (200, "h1"),
        (400, "r4"),
        (400, "h1"),
        (600, "r4"),
        (600, "h1"),
    ]
    assert all(set(r) == set(EVAL_FIELDS) for r in rows)
    again = evaluate_snapshots(
        cfg, res.snapshots, ["r4", "h1"], steps=200, seed=5, episode_steps=100
    )
    assert again == rows
