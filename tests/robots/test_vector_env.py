"""``dfrl/EPuck-v0`` as a vector environment (``gymnasium.make_vec``, the batched simulator),
checked against Gymnasium's own vector machinery and against the pybullet ``EPuckEnv``
(real components, no mocks).

Gymnasium 1.x has no checker for vector environments (``gymnasium.utils.env_checker`` checks a
single ``Env``); these tests use what it does have: ``passive_env_checker.check_obs`` on every
batch, ``env_checker.data_equivalence`` for determinism, ``SyncVectorEnv`` over ``EPuckEnv`` for
the shape of infos, and the vector wrappers ``RecordEpisodeStatistics`` and ``DictInfoToList``,
which rely on the autoreset mode and the ``_key`` masks.
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.utils.passive_env_checker import check_obs
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.vector.utils import batch_space
from gymnasium.wrappers.vector import DictInfoToList, RecordEpisodeStatistics

import dfrl.robots  # noqa: F401 - registers dfrl/EPuck-v0
from dfrl.arenas import load_arena
from dfrl.robots.batched.world import BatchedWorld
from dfrl.robots.env import EnvConfig, EPuckEnv
from dfrl.robots.epuck import EPuckConfig
from dfrl.robots.registration import ENV_ID
from dfrl.robots.vector_env import INFO_KEYS, EPuckVectorEnv
from dfrl.robots.world import SimConfig

#: Largest IR difference allowed between the batched simulator and pybullet at the same pose,
#: as a distance (m). Measured over 2,800 respawn poses in the seven built-in arenas: 98.8% of
#: the 1,085 readings that saw something were bit-equal (float32), the 99th percentile differed
#: by 0.12 mm, the largest by 1.83 mm: rays that pass within a few mm of a block's corner, where
#: pybullet's ray test hits up to ~1 mm outside the box (its collision margin rounds the corner;
#: the kernels' boxes are sharp).
IR_TOLERANCE_M = 0.0025


def make(num_envs: int, **kwargs: object) -> EPuckVectorEnv:
    env = gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
    assert isinstance(env, EPuckVectorEnv)
    return env


def rollout(env: EPuckVectorEnv, seed: int, steps: int) -> list[tuple]:
    """Everything ``reset(seed)`` and ``steps`` seeded random steps return."""
    env.action_space.seed(seed)
    out: list[tuple] = [env.reset(seed=seed)]
    for _ in range(steps):
        out.append(env.step(env.action_space.sample()))
    return out


def drive_until_done(env: EPuckVectorEnv, action: int, limit: int = 200) -> int:
    """Step every sub-environment with ``action`` until one ends its episode; the steps."""
    for k in range(1, limit + 1):
        _, _, terminated, truncated, _ = env.step(np.full(env.num_envs, action))
        if terminated.any() or truncated.any():
            return k
    raise AssertionError(f"no episode ended in {limit} steps")


def test_make_vec_builds_the_batched_vector_env() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # e.g. make_vec's missing-autoreset warning
        env = make(3, arena="r1", stuck_steps=40, actions="extended")
    assert env.num_envs == 3 and env.spec is not None and env.spec.id == ENV_ID
    assert env.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert env.single_observation_space == gym.spaces.Box(0.0, 1.0, (8,), np.float32)
    assert env.single_action_space == gym.spaces.Discrete(5)
    assert env.observation_space == batch_space(env.single_observation_space, 3)
    assert env.action_space == gym.spaces.MultiDiscrete([5, 5, 5])
    assert env.config.stuck_steps == 40 and env.max_episode_steps == 1000  # the registered
    assert [a.name for a in env.arenas] == ["r1"] * 3
    mixed = make(2, arena=["r1", load_arena("r4")], max_episode_steps=50)
    assert [a.name for a in mixed.arenas] == ["r1", "r4"] and mixed.max_episode_steps == 50


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="2 arenas for 3"):
        make(3, arena=["r1", "r2"])
    with pytest.raises(ValueError, match="render_mode"):
        make(1, render_mode="rgb_array")
    with pytest.raises(ValueError, match="stuck_steps"):
        make(1, stuck_steps=-1)
    env = make(2)
    env.reset(seed=0)
    for bad in ([0, 3], [0], [0.0, 1.0], np.array([[0, 1]])):
        with pytest.raises(ValueError, match="2 integers in 0..2"):
            env.step(bad)
    with pytest.raises(ValueError, match="3 seeds for 2"):
        env.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset(options={"reset_mask": np.zeros(2, dtype=bool)})
    with pytest.raises(ValueError, match="unknown options"):
        env.reset(options={"poses": (0.0, 0.0, 0.0)})


def test_registration_imports_neither_pybullet_nor_numba() -> None:
    code = (
        "import sys, gymnasium, dfrl.robots\n"
        "print(gymnasium.spec('dfrl/EPuck-v0').vector_entry_point)\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('pybullet', 'numba')))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[:2] == ["dfrl.robots.vector_env:EPuckVectorEnv", "[]"]


def test_reset_and_step_return_batches_of_the_declared_spaces() -> None:
    env = make(4, arena="r4", stuck_steps=20)
    obs, infos = env.reset(seed=5)
    check_obs(obs, env.observation_space, "reset")
    assert set(infos) == set(INFO_KEYS) | {f"_{k}" for k in INFO_KEYS}
    env.action_space.seed(5)
    for _ in range(60):
        obs, rewards, terminated, truncated, infos = env.step(env.action_space.sample())
        check_obs(obs, env.observation_space, "step")
        assert rewards.shape == (4,) and rewards.dtype == np.float64
        assert terminated.dtype == truncated.dtype == np.bool_
        assert terminated.shape == truncated.shape == (4,)
        assert infos["collision"].dtype == infos["stuck"].dtype == np.bool_
        assert infos["progress"].shape == (4,) and infos["pose"].shape == (4, 3)
        assert infos["distances"].shape == (4, 8)
        assert all(infos[f"_{k}"].all() for k in INFO_KEYS)
        np.testing.assert_array_equal(infos["pose"], env.pose)


def test_infos_have_the_keys_of_a_sync_vector_env_of_epuck_envs() -> None:
    sync = SyncVectorEnv([lambda: EPuckEnv(arena="r4") for _ in range(2)])
    try:
        ours = make(2, arena="r4")
        for a, b in (
            (sync.reset(seed=1), ours.reset(seed=1)),
            (sync.step(np.array([0, 1])), ours.step(np.array([0, 1]))),
        ):
            assert set(a[-1]) == set(b[-1])
            assert [np.shape(x) for x in a[:-1]] == [np.shape(x) for x in b[:-1]]
            assert [np.asarray(x).dtype for x in a[:-1]] == [np.asarray(x).dtype for x in b[:-1]]
    finally:
        sync.close()


def test_same_seed_same_trajectories_whatever_else_is_in_the_batch() -> None:
    # stuck after 10 steps, so respawns and autoresets happen within the 150 steps
    first = rollout(make(3, arena="r4", stuck_steps=10), seed=7, steps=150)
    second = rollout(make(3, arena="r4", stuck_steps=10), seed=7, steps=150)
    assert data_equivalence(first, second, exact=True)
    assert sum(int(s[2].sum() + s[3].sum()) for s in first[1:]) >= 3  # episodes did end
    # sub-environment 2 of seed 7 is a lone environment seeded 9, driven by the same actions
    batch, lone = make(3, arena="r4", stuck_steps=10), make(1, arena="r4", stuck_steps=10)
    batch.action_space.seed(7)
    obs_b, _ = batch.reset(seed=7)
    obs_l, _ = lone.reset(seed=9)
    for _ in range(150):
        actions = batch.action_space.sample()
        obs_b, r_b, te_b, tr_b, _ = batch.step(actions)
        obs_l, r_l, te_l, tr_l, _ = lone.step(actions[2:])
        assert np.array_equal(obs_b[2:], obs_l) and r_b[2] == r_l[0]
        assert (te_b[2], tr_b[2]) == (te_l[0], tr_l[0])
    other = rollout(make(3, arena="r4", stuck_steps=10), seed=8, steps=150)
    assert not data_equivalence(first, other)


def test_first_observations_match_pybullet_at_the_same_pose() -> None:
    """A seeded reset puts both at the arena's start pose; the resets after it draw the same
    random free poses from the same generator (poses equal exactly); the IR readings agree
    within :data:`IR_TOLERANCE_M` and nearly all bit for bit."""
    seen = equal = 0
    for arena in ("r1", "r2", "r3", "r4", "r5", "h1", "h2"):
        single = EPuckEnv(arena=arena)
        vector = make(1, arena=arena)
        try:
            for seed in range(3):
                pairs = [(single.reset(seed=seed), vector.reset(seed=seed))]
                pairs += [(single.reset(), vector.reset()) for _ in range(30)]
                for (obs1, info1), (obs2, info2) in pairs:
                    assert np.array_equal(np.asarray(info1["pose"]), info2["pose"][0])
                    diff = np.abs(obs1 - obs2[0]) * single.config.sim.robot.sensor_range
                    assert diff.max() <= IR_TOLERANCE_M, (arena, seed, diff)
                    looked = (obs1 > 0) | (obs2[0] > 0)
                    seen += int(looked.sum())
                    equal += int((looked & (obs1 == obs2[0])).sum())
        finally:
            single.close()
    assert seen > 100 and equal >= 0.95 * seen


def test_a_collision_terminates_and_the_next_step_resets_as_epuck_env_would() -> None:
    arena = load_arena("r5")
    rim = EnvConfig().sim.robot.body_radius
    near_wall = (0.5 - rim - 0.02, 0.0, 0.0)  # 2 cm from the +x wall, facing it
    env = make(2, arena="r5", stuck_steps=0)
    env.reset(seed=11, options={"pose": near_wall})
    k = drive_until_done(env, action=0)
    assert 1 <= k <= 5
    # both robots hit the wall at the same step; the step after resets them
    obs, rewards, terminated, truncated, infos = env.step(np.array([0, 0]))
    assert not terminated.any() and not truncated.any() and (rewards == 0.0).all()
    assert not infos["collision"].any() and (infos["progress"] == 0.0).all()
    # the reset draws a random free pose from each generator as EPuckEnv.reset() would: the
    # generators, seeded 11 and 12, drew nothing else (no sensor noise)
    clearance = rim + 0.03
    for i, seed in enumerate((11, 12)):
        expected = arena.sample_free_pose(np.random.default_rng(seed), clearance)
        np.testing.assert_allclose(infos["pose"][i], expected, rtol=0, atol=1e-12)
    check_obs(obs, env.observation_space, "step")
    # the pybullet environment, same seed, same pose, same actions: the same respawn
    single = EPuckEnv(arena="r5", stuck_steps=0)
    try:
        single.reset(seed=11, options={"pose": near_wall})
        while not single.step(0)[2]:
            pass
        assert np.array_equal(np.asarray(single.reset()[1]["pose"]), infos["pose"][0])
    finally:
        single.close()


def test_an_autoreset_draws_only_what_the_reset_draws() -> None:
    """With sensor noise every observation draws 8 normals; the step thrown away for a robot
    being reset must not advance its generator."""
    std = 0.002
    sim = SimConfig(robot=EPuckConfig(sensor_noise_std=std))
    rim = sim.robot.body_radius
    env = make(1, arena="r5", sim=sim, stuck_steps=0)
    env.reset(seed=3, options={"pose": (0.5 - rim - 0.02, 0.0, 0.0)})
    k = drive_until_done(env, action=0)
    _, _, _, _, infos = env.step(np.array([0]))
    rng = np.random.default_rng(3)
    rng.normal(0.0, std, size=(k + 1, 8))  # the reset's and the k steps' readings
    expected = load_arena("r5").sample_free_pose(rng, rim + 0.03)
    np.testing.assert_allclose(infos["pose"][0], expected, rtol=0, atol=1e-12)


def test_an_autoreset_leaves_no_trace_of_the_step_it_throws_away() -> None:
    """The vector env against a world built with the same seed and driven by hand, which
    respawns a robot instead of stepping it: the same poses and observations throughout (the
    motion's spread draws 3 normals a step from its own generator)."""
    env = make(1, arena="r4", stuck_steps=10)
    world = BatchedWorld(EnvConfig(stuck_steps=10), ["r4"], [np.random.default_rng(5)])
    env.reset(seed=5)
    world.start(0)
    rng = np.random.default_rng(0)
    ended, resets = False, 0
    for _ in range(300):
        actions = rng.integers(3, size=1)
        obs, _, terminated, truncated, infos = env.step(actions)
        if ended:
            world.respawn(0)
            resets += 1
        else:
            world.step(actions)
        ended = bool(terminated[0] or truncated[0])
        assert np.array_equal(infos["pose"][0], world.pose[0])
        assert np.array_equal(obs, world.observations())
    assert resets >= 3


def test_stuck_and_time_limit_truncate() -> None:
    env = make(2, arena="r5", stuck_steps=5, max_episode_steps=100)
    env.reset(seed=0)
    assert drive_until_done(env, action=1) == 5  # spinning: moved < 3 cm over 5 steps
    single = EPuckEnv(arena="r5", stuck_steps=5)
    try:
        single.reset(seed=0)
        assert [single.step(1)[3] for _ in range(5)] == [False] * 4 + [True]  # as pybullet
    finally:
        single.close()
    env = make(2, arena="r5", stuck_steps=0, max_episode_steps=7)
    env.reset(seed=0)
    assert drive_until_done(env, action=1) == 7
    _, _, terminated, truncated, _ = env.step(np.array([1, 1]))  # the autoreset
    assert not terminated.any() and not truncated.any()
    assert drive_until_done(env, action=1) == 7  # a new episode's 7 steps


def test_reset_mask_resets_only_the_masked() -> None:
    env = make(3, arena="r4")
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.array([0, 1, 2]))
    before = env.pose
    obs, infos = env.reset(options={"reset_mask": np.array([False, True, False])})
    after = env.pose
    assert np.array_equal(before[[0, 2]], after[[0, 2]])
    assert not np.array_equal(before[1], after[1])
    assert infos["_pose"].tolist() == [False, True, False]
    assert np.array_equal(infos["pose"][1], after[1]) and not infos["pose"][0].any()
    assert np.array_equal(obs, env.world.observations())


def test_gymnasium_vector_wrappers_see_episodes_and_masks() -> None:
    env = RecordEpisodeStatistics(make(2, arena="r5", stuck_steps=0, max_episode_steps=9))
    env.reset(seed=0)
    for _ in range(9):
        _, _, _, truncated, infos = env.step(np.array([1, 2]))
    assert truncated.all() and infos["_episode"].all()
    assert infos["episode"]["l"].tolist() == [9, 9]
    listed = DictInfoToList(make(2, arena="r5"))
    _, infos = listed.reset(seed=0)
    assert isinstance(infos, list) and len(infos) == 2
    assert set(infos[0]) == set(INFO_KEYS)
    assert math.isclose(infos[1]["pose"][0], 0.0) and not infos[1]["collision"]
