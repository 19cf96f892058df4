"""Sensing and one-step transitions of the two simulators from the same states."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np

from dfrl.arenas.spec import ArenaSpec, load_arena
from dfrl.robots.batched.world import BatchedWorld
from dfrl.robots.env import EnvConfig, EPuckEnv
from dfrl.robots.state import Discretiser, DiscretisationConfig


def _batched(config: EnvConfig, arena: ArenaSpec, seed: int) -> BatchedWorld:
    return BatchedWorld(config, [arena], [np.random.default_rng(seed)])


def compare_sensing(
    config: EnvConfig, arena: str | ArenaSpec, poses: int, seed: int
) -> dict[str, Any]:
    """IR distances of both simulators at ``poses`` random free poses (clearance: the body).

    Returns
    -------
    dict
        ``readings``; ``mean_abs_mm``, ``p99_abs_mm`` and ``max_abs_mm`` of the per-sensor
        differences; ``state_agreement``: the share of poses with the same tabular state.
    """
    spec = arena if isinstance(arena, ArenaSpec) else load_arena(arena)
    env = EPuckEnv(arena=spec, config=config)
    world = _batched(config, spec, seed)
    disc = Discretiser(DiscretisationConfig())
    rng = np.random.default_rng(seed)
    errors, same = [], 0
    try:
        env.reset(seed=seed)
        for _ in range(poses):
            pose = spec.sample_free_pose(rng, config.sim.robot.body_radius)
            env.world.place_robot(*pose)
            reading = env.robot.sense()
            world.place(0, pose)
            errors.append(np.abs(world.dist[0] - reading))
            same += disc(env.robot.proximity(reading).astype(np.float32)) == disc(
                world.observations()[0]
            )
    finally:
        env.close()
    err = np.concatenate(errors) * 1000.0
    return {
        "readings": int(err.size),
        "mean_abs_mm": float(err.mean()),
        "p99_abs_mm": float(np.percentile(err, 99)),
        "max_abs_mm": float(err.max()),
        "state_agreement": same / poses,
    }


def _walk(
    env: EPuckEnv, disc: Discretiser, steps: int, rng: np.random.Generator
) -> list[tuple[tuple[float, float, float], int, int, int, int]]:
    """A pybullet random walk: (pose, previous action + 1, action, state, next state)."""
    rows = []
    obs, _ = env.reset()
    prev = -1
    for _ in range(steps):
        action = prev if prev >= 0 and rng.random() < 0.5 else int(rng.integers(3))
        pose, state = env.pose, disc(obs)
        obs, _, terminated, truncated, info = env.step(action)
        rows.append((pose, prev + 1, action, state, disc(obs)))
        prev = action
        if terminated or truncated or info["collision"]:
            obs, _ = env.reset()
            prev = -1
    return rows


def _replay(
    world: BatchedWorld,
    disc: Discretiser,
    rows: list[tuple[tuple[float, float, float], int, int, int, int]],
) -> list[int]:
    nexts = []
    for pose, prev, action, _, _ in rows:
        world.place(0, pose)
        world.prev[0] = prev
        world.step(np.array([action]))
        nexts.append(disc(world.observations()[0]))
    return nexts


def _tv(rows: list[tuple[int, int]], a: list[int], b: list[int]) -> float:
    """Visit-weighted total variation distance between the next-state distributions of
    ``a`` and ``b`` per (state, action) key of ``rows``."""
    groups: dict[tuple[int, int], list[int]] = defaultdict(list)
    for k, key in enumerate(rows):
        groups[key].append(k)
    total = 0.0
    for members in groups.values():
        ca: dict[int, int] = defaultdict(int)
        cb: dict[int, int] = defaultdict(int)
        for k in members:
            ca[a[k]] += 1
            cb[b[k]] += 1
        m = len(members)
        tv = 0.5 * sum(abs(ca[s] - cb[s]) for s in set(ca) | set(cb)) / m
        total += m * tv
    return total / len(rows)


def compare_transitions(
    config: EnvConfig, arena: str | ArenaSpec, steps: int, seed: int
) -> dict[str, Any]:
    """One-step outcomes from the states of a pybullet random walk, replayed in batched.

    Returns
    -------
    dict
        ``transitions``; ``agreement`` (same next state as pybullet), ``tv_distance``
        (pybullet against batched, visit-weighted over (state, action)) and ``tv_floor`` (two
        batched replays with different motion-noise draws against each other).
    """
    spec = arena if isinstance(arena, ArenaSpec) else load_arena(arena)
    disc = Discretiser(DiscretisationConfig())
    env = EPuckEnv(arena=spec, config=config)
    try:
        env.reset(seed=seed)
        rows = _walk(env, disc, steps, np.random.default_rng(seed))
    finally:
        env.close()
    pb = [r[4] for r in rows]
    first = _replay(_batched(config, spec, seed), disc, rows)
    second = _replay(_batched(config, spec, seed + 1), disc, rows)
    keys = [(r[3], r[2]) for r in rows]
    return {
        "transitions": len(rows),
        "agreement": float(np.mean([x == y for x, y in zip(pb, first)])),
        "tv_distance": _tv(keys, pb, first),
        "tv_floor": _tv(keys, second, first),
    }
