"""The simulated e-puck and its Gymnasium environment (real pybullet, no mocks)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import dfrl.robots  # noqa: F401 - registers dfrl/EPuck-v0
from dfrl.arenas import builtin_arena_names, load_arena
from dfrl.robots.env import EnvConfig, EPuckEnv
from dfrl.robots.epuck import EPuckConfig
from dfrl.robots.world import SimConfig, World


def test_physics_rate_must_divide_control_rate() -> None:
    assert SimConfig(control_dt=0.064, physics_dt=0.008).substeps == 8
    assert SimConfig(control_dt=0.064, physics_dt=0.004).substeps == 16
    with pytest.raises(ValueError, match="integer multiple"):
        SimConfig(control_dt=0.064, physics_dt=0.005)
    with pytest.raises(ValueError, match="positive"):
        SimConfig(control_dt=0.064, physics_dt=0.0)


def test_wheels_drive_the_body() -> None:
    world = World(load_arena("r5"))
    try:
        world.place_robot(-0.3, 0.0, 0.0)
        v = world.config.robot.max_wheel_speed
        for _ in range(25):  # 1.6 s at top speed (about 13 cm/s)
            world.step(v, v)
        x, y, yaw = world.robot.pose()
        assert 0.15 < x + 0.3 < 0.22 and abs(y) < 0.01 and abs(yaw) < 0.05
        for _ in range(10):  # spin on the spot to the left
            world.step(-v / 2, v / 2)
        x2, y2, yaw2 = world.robot.pose()
        assert yaw2 > 1.0 and math.hypot(x2 - x, y2 - y) < 0.02
        assert world.sim_time == pytest.approx(35 * 0.064)
    finally:
        world.close()


def test_ir_sensors_see_a_few_centimetres_and_collisions_register() -> None:
    world = World(load_arena("r5"))
    try:
        rc = world.config.robot
        world.place_robot(0.0, 0.0, 0.0)
        assert np.all(world.robot.sense() == rc.sensor_range)
        # facing the +x wall from 3 cm: front sensors read about 3 cm, rear sensors nothing
        world.place_robot(0.5 - rc.body_radius - 0.03, 0.0, 0.0)
        d = world.robot.sense()
        assert d[0] == pytest.approx(
            0.03 / math.cos(0.30) + rc.body_radius * (1 - math.cos(0.30)) / math.cos(0.30),
            abs=0.004,
        )
        assert d[3] == rc.sensor_range and d[4] == rc.sensor_range
        assert not world.in_collision()
        for _ in range(20):
            world.step(rc.max_wheel_speed, rc.max_wheel_speed)
            if world.in_collision():
                break
        assert world.in_collision()
        assert world.robot.sense()[[0, 7]].max() < 0.005
    finally:
        world.close()


def test_sensor_noise_uses_the_given_rng() -> None:
    world = World(load_arena("r5"), SimConfig(robot=EPuckConfig(sensor_noise_std=0.003)))
    try:
        world.place_robot(0.5 - 0.037 - 0.03, 0.0, 0.0)
        a = world.robot.sense(np.random.default_rng(1))
        b = world.robot.sense(np.random.default_rng(1))
        c = world.robot.sense(np.random.default_rng(2))
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, c)
        assert a[3] == 0.06  # nothing seen: no noise
        with pytest.raises(ValueError, match="rng"):
            world.robot.sense()
    finally:
        world.close()


@pytest.mark.parametrize("arena", builtin_arena_names())
def test_check_env_passes(arena: str) -> None:
    env = gym.make("dfrl/EPuck-v0", arena=arena)
    try:
        check_env(env.unwrapped)
    finally:
        env.close()


@pytest.mark.parametrize("arena", builtin_arena_names())
def test_same_seed_same_step_in_one_env(arena: str) -> None:
    # A teleport kept the solver's contact state: in R1, reset(seed=123); step(0) alternated
    # between two rewards. Seeded resets now rebuild the world.
    env = EPuckEnv(arena, EnvConfig())
    try:
        steps = []
        for _ in range(3):
            env.reset(seed=123)
            obs, reward, *_ = env.step(0)
            steps.append((obs.tolist(), reward))
        assert steps[0] == steps[1] == steps[2]
    finally:
        env.close()


def test_reset_with_seed_is_reproducible() -> None:
    def rollout(seed: int) -> list:
        env = EPuckEnv("r4", EnvConfig())
        try:
            obs, _ = env.reset(seed=seed, options={"random": True})
            trace = [obs.tolist()]
            env.reset()  # a random free pose drawn from np_random
            for i in range(60):
                obs, r, term, trunc, info = env.step(i % 3)
                trace.append((obs.tolist(), r, term, trunc, info["pose"]))
                if term or trunc:
                    env.reset()
            return trace
        finally:
            env.close()

    assert rollout(5) == rollout(5)
    assert rollout(5) != rollout(6)


def test_collision_terminates_and_reward_penalises() -> None:
    env = EPuckEnv("r5")
    try:
        env.reset(seed=0, options={"pose": (0.38, 0.0, 0.0)})
        rewards, term = [], False
        for _ in range(40):
            _, r, term, _, info = env.step(0)  # forward into the wall
            rewards.append(r)
            if term:
                break
        assert term and info["collision"]
        assert rewards[1] == pytest.approx(1.0, abs=0.01)  # free forward motion at top speed
        assert rewards[-1] < -9  # collision
        assert min(rewards[:-1]) < 0.5  # near-contact penalty before the crash
        obs, info = env.reset()
        assert env.arena.is_free(info["pose"][0], info["pose"][1], 0.06)
    finally:
        env.close()


def test_stuck_robot_is_truncated() -> None:
    env = EPuckEnv("r5", stuck_steps=20)
    try:
        env.reset(seed=0)
        truncs = [env.step(1)[3] for _ in range(21)]  # spinning on the spot
        assert not any(truncs[:19]) and truncs[20]
    finally:
        env.close()


def test_rgb_render_is_a_top_view() -> None:
    env = gym.make("dfrl/EPuck-v0", arena="r1", render_mode="rgb_array")
    try:
        env.reset(seed=0)
        img = env.render()
        assert img.shape == (480, 480, 3) and img.dtype == np.uint8
        # the block in the middle is red-ish, the floor near the corner is light
        assert img[240, 240, 0] > 150 and img[240, 240, 1] < 120
        assert img[60, 400].min() > 180
    finally:
        env.close()


def test_sensor_rays_end_where_the_sensors_see_a_wall() -> None:
    # Prepare: the empty arena R5 (walls' inner faces at x, y = +-0.5), robot facing +x.
    world = World(load_arena("r5"), SimConfig())
    try:
        world.place_robot(0.43, 0.0, 0.0)
        # Execute
        rays = world.robot.sensor_rays(world.robot.sense())
        # Assert: the two front sensors (ps0, ps7 at -+0.3 rad) end on the wall, the side and
        # rear ones a full range away from the rim; every ray starts on the rim.
        rim = EPuckConfig().body_radius
        assert rays.shape == (8, 2, 2)
        assert np.allclose(np.hypot(rays[:, 0, 0] - 0.43, rays[:, 0, 1]), rim)
        assert rays[0, 1, 0] == pytest.approx(0.5, abs=2e-3)
        assert rays[7, 1, 0] == pytest.approx(0.5, abs=2e-3)
        lengths = np.hypot(*(rays[:, 1] - rays[:, 0]).T)
        assert np.allclose(lengths[2:6], EPuckConfig().sensor_range)
    finally:
        world.close()
