"""The batched simulator against the pybullet reference (real pybullet, real numba kernels)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfrl.arenas.spec import ArenaError, load_arena
from dfrl.experiments.science.fidelity.policies import compare_policies
from dfrl.experiments.science.fidelity.sensing import compare_sensing, compare_transitions
from dfrl.robots.batched.evaluation import evaluate_greedy
from dfrl.robots.batched.training import BatchedTrainer, BatchError
from dfrl.robots.batched.world import BatchedWorld
from dfrl.robots.env import EnvConfig, EPuckEnv
from dfrl.robots.evaluation import PolicyKind, evaluate_policy
from dfrl.robots.training import TrainerConfig
from tests.robots.batched.made_arena import make_arena


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(make_arena(tmp_path_factory.mktemp("arena") / "made.json", seed=11))


@pytest.mark.parametrize("arena", ["r4", "h1", "made"])
def test_ir_readings_match_pybullet_at_the_same_poses(arena: str, made: str) -> None:
    name = made if arena == "made" else arena
    r = compare_sensing(EnvConfig(arena=name), name, poses=300, seed=3)
    # a grazing ray can differ by mm (pybullet's face tolerance), 99% of readings do not
    assert r["p99_abs_mm"] < 1.0
    assert r["mean_abs_mm"] < 0.2
    assert r["state_agreement"] > 0.97


def test_low_blocks_collide_but_are_not_seen(made: str) -> None:
    spec = load_arena(made)
    low = [b for b in spec.blocks if b.size[2] < 0.03]
    assert low, "the made-up arena has a block below the rays"
    b = low[0]
    world = BatchedWorld(EnvConfig(arena=made), [made], [np.random.default_rng(0)])
    # facing the block's centre from just beyond its footprint: nothing seen ahead
    far = max(b.size[0], b.size[1]) / 2 + 0.045
    for angle in np.linspace(-np.pi, np.pi, 16, endpoint=False):
        x, y = b.center[0] + far * np.cos(angle), b.center[1] + far * np.sin(angle)
        if spec.is_free(x, y, 0.038):
            world.place(0, (x, y, angle + np.pi))
            break
    else:
        pytest.skip("no free pose beside the low block")
    env = EPuckEnv(arena=made)
    try:
        env.reset(seed=0)
        env.world.place_robot(*world.pose[0])
        assert np.allclose(env.robot.sense(), world.dist[0], atol=1e-3)
    finally:
        env.close()


@pytest.mark.parametrize("arena", ["r1", "made"])
def test_one_step_outcomes_match_pybullet(arena: str, made: str) -> None:
    name = made if arena == "made" else arena
    r = compare_transitions(EnvConfig(arena=name), name, steps=1500, seed=5)
    assert r["agreement"] > 0.95
    assert r["tv_distance"] < 0.05
    assert r["tv_distance"] < r["tv_floor"] + 0.02  # no more than the motion noise explains


def test_fixed_policies_collide_as_in_pybullet() -> None:
    r = compare_policies(EnvConfig(arena="r4"), "r4", steps=4000, seed=2)
    # driving ahead: each collision after the same number of steps from the same respawn poses
    ahead = r["ahead"]
    gap = ahead["batched"]["collisions_per_1000"] - ahead["pybullet"]["collisions_per_1000"]
    assert abs(gap) < 2.0
    assert abs(r["uniform"]["progress_difference"][0]) < 0.03


def test_the_same_seed_learns_the_same_table_whatever_the_batch() -> None:
    base = TrainerConfig(arena="r4")
    alone = BatchedTrainer([base.replace(seed=7)])
    alone.run(1500)
    mixed = [(3, "r1"), (7, "r4"), (9, "h2")]
    crowd = BatchedTrainer([base.replace(seed=s, arena=a) for s, a in mixed])
    crowd.run(700)
    crowd.run(800)
    assert np.array_equal(alone.q[0], crowd.q[1])
    assert alone.collisions[0] == crowd.collisions[1]
    assert not np.array_equal(crowd.q[0], crowd.q[1])


def test_learning_beats_the_untrained_table_in_pybullet() -> None:
    base = TrainerConfig(arena="r1")
    bt = BatchedTrainer([base.replace(seed=s) for s in range(4)])
    bt.run(8000)
    learnt = [
        evaluate_policy(base, PolicyKind.GREEDY, 600, 100 + k, q_table=bt.q[k], episode_steps=200)
        for k in range(4)
    ]
    zero = [
        evaluate_policy(
            base, PolicyKind.GREEDY, 600, 100 + k, q_table=np.zeros_like(bt.q[k]), episode_steps=200
        )
        for k in range(4)
    ]
    score = lambda r: r.progress - 0.05 * r.collisions_per_1000  # noqa: E731
    assert np.mean([score(r) for r in learnt]) > np.mean([score(r) for r in zero]) + 0.2


def test_batched_evaluation_measures_as_pybullet_does() -> None:
    base = TrainerConfig(arena="r4")
    ahead = np.zeros((81, 3))
    ahead[:, 0] = 1.0  # always forward
    b = evaluate_greedy(base, [ahead], ["r4"], 3000, [21], episode_steps=300)[0]
    p = evaluate_policy(base, PolicyKind.GREEDY, 3000, 21, q_table=ahead, episode_steps=300)
    assert b.episodes == p.episodes == 10
    assert abs(b.collisions_per_1000 - p.collisions_per_1000) < 4.0
    assert abs(b.progress - p.progress) < 0.02
    assert abs(b.coverage - p.coverage) < 0.03


def test_what_the_batch_cannot_run_is_refused() -> None:
    base = TrainerConfig(arena="r4")
    with pytest.raises(BatchError, match="robot 1: learner 'dqn'"):
        BatchedTrainer([base, base.replace(algo="dqn")])
    with pytest.raises(BatchError, match="'stuck_steps' differs"):
        BatchedTrainer([base, base.replace(stuck_steps=10)])
    with pytest.raises(ValueError, match="3 tables, 2 arenas"):
        evaluate_greedy(base, [np.zeros((81, 3))] * 3, ["r4", "r4"], 10, 1)


def test_a_crowded_arena_is_a_located_error(tmp_path: Path) -> None:
    path = tmp_path / "crowded.json"
    path.write_text(
        '{"name": "crowded", "size": [0.12, 0.12], "wall_height": 0.1, "blocks": [], '
        '"start": {"pose": [0, 0, 0]}}',
        encoding="utf-8",
    )
    world = BatchedWorld(EnvConfig(), [str(path)], [np.random.default_rng(0)])
    with pytest.raises(ArenaError, match="crowded.json: no free pose"):
        world.respawn(0)


@pytest.mark.parametrize("mode", ["centred_no_bootstrap", "centred", "raw"])
def test_the_learning_control_draws_as_the_reference_does(mode: str) -> None:
    from dfrl.robots.batched.shuffle import MODES, learnt_outcome
    from dfrl.robots.reward_shuffle import RewardShuffle, ShuffleMode

    cap, rng = 7, np.random.default_rng(4)
    outcomes = [(float(rng.normal()), bool(rng.random() < 0.2)) for _ in range(40)]
    reference = RewardShuffle(cap, np.random.default_rng(99), mode)
    buffer, total = np.zeros((1, cap, 2)), np.zeros(1)
    meta = np.array([[cap, MODES[ShuffleMode(mode)], 0, 0]], dtype=np.int64)
    draws = np.random.default_rng(99)
    for r, end in outcomes:
        want = reference(r, end)
        got = learnt_outcome(0, r, end, buffer, meta, total, draws)
        assert got[1] == want[1] and got[0] == pytest.approx(want[0], abs=1e-12)


def test_a_control_robot_learns_nothing_of_the_task() -> None:
    base = TrainerConfig(arena="r1")
    bt = BatchedTrainer(
        [base.replace(seed=s) for s in range(3)]
        + [base.replace(seed=s, reward_shuffle=500) for s in range(3)]
    )
    bt.run(6000)
    trained, control = bt.q[:3], bt.q[3:]
    assert np.abs(control).max() < np.abs(trained).max() / 2  # values stay near 0
    assert np.array_equal(bt.collisions[:3] > 0, [True] * 3)


def test_linear_features_are_the_reference_feature_map() -> None:
    from dfrl.robots.batched.linear import active_features as batched_features
    from dfrl.robots.features import TileCoding, active_features

    rng = np.random.default_rng(8)
    coding = TileCoding(tilings=4, tiles=8)
    out = np.zeros(coding.n_active(8), dtype=np.int64)
    for dist in [np.full(8, 0.06), np.zeros(8)] + [rng.uniform(0, 0.06, 8) for _ in range(200)]:
        batched_features(dist, 0.06, 4, 8, out)
        obs = (1.0 - dist / 0.06).astype(np.float32).astype(np.float64)
        assert np.array_equal(out, active_features(obs, coding))


def test_linear_robots_learn_in_batch_and_act_well_in_pybullet() -> None:
    from dfrl.robots.batched.linear import BatchedLinearTrainer

    base = TrainerConfig(arena="r1", algo="linear")
    bt = BatchedLinearTrainer([base.replace(seed=s) for s in range(3)])
    bt.run(3000)
    again = BatchedLinearTrainer([base.replace(seed=1)])
    again.run(3000)
    assert np.array_equal(bt.weights[1], again.weights[0])  # the seed, not the batch
    score = lambda r: r.progress - 0.05 * r.collisions_per_1000  # noqa: E731
    learnt = [
        score(
            evaluate_policy(
                base, PolicyKind.GREEDY, 600, 40 + k, params=bt.params(k), episode_steps=200
            )
        )
        for k in range(3)
    ]
    untrained = BatchedLinearTrainer([base.replace(seed=9)]).params(0)
    flat = [
        score(
            evaluate_policy(
                base, PolicyKind.GREEDY, 600, 40 + k, params=untrained, episode_steps=200
            )
        )
        for k in range(3)
    ]
    assert np.mean(learnt) > np.mean(flat) + 0.2
    bt.set_params(0, bt.params(2))
    assert np.array_equal(bt.weights[0], bt.weights[2])
    with pytest.raises(ValueError):
        bt.set_params(0, np.zeros(5))
    with pytest.raises(BatchError, match="'qlearning' is not batched here"):
        BatchedLinearTrainer([base.replace(algo="qlearning")])


def test_wandering_robots_respawn_and_repeat_with_their_seeds() -> None:
    def walk(seeds: list[int]) -> BatchedWorld:
        world = BatchedWorld(
            EnvConfig(arena="r4"), ["r4"] * len(seeds), [np.random.default_rng(s) for s in seeds]
        )
        for i in range(world.n):
            world.start(i)
        world.wander(3000, [np.random.default_rng([s, 1]) for s in seeds])
        return world

    a, b = walk([1, 2]), walk([2])
    assert np.array_equal(a.pose[1], b.pose[0])
    assert not np.array_equal(a.pose[0], a.pose[1])
    # 3,000 random steps in R4 collide (about 10 per 1,000): every robot is still on the floor
    assert np.all(np.abs(a.pose[:, :2]) < 0.5)
    assert np.all([a.arenas[0].is_free(x, y, 0.036) for x, y in a.pose[:, :2]])
