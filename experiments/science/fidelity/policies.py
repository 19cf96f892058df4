"""Fixed policies in both simulators: collisions per 1,000 steps and progress."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from dfrl.arenas.spec import ArenaSpec, load_arena
from dfrl.experiments.science.statistics import welch
from dfrl.robots.batched.world import BatchedWorld
from dfrl.robots.env import EnvConfig, EPuckEnv

#: steps of a block: the unit of the intervals
BLOCK: int = 1000

Rule = Callable[[np.ndarray, np.random.Generator], int]


def avoid(obs: np.ndarray, rng: np.random.Generator) -> int:
    """Ahead unless a front sensor sees something within 70% of its range; then turn away."""
    if max(obs[0], obs[1], obs[6], obs[7]) > 0.3:
        return 1 if obs[0] + obs[1] > obs[6] + obs[7] else 2
    return 0


def uniform(obs: np.ndarray, rng: np.random.Generator) -> int:
    """A uniformly random action."""
    return int(rng.integers(3))


def ahead(obs: np.ndarray, rng: np.random.Generator) -> int:
    """Always ahead (into the next wall)."""
    return 0


#: The fixed policies compared, by name.
POLICIES: dict[str, Rule] = {"avoid": avoid, "uniform": uniform, "ahead": ahead}


def _blocks(collided: list[bool], progress: list[float]) -> tuple[list[float], list[float]]:
    n = len(collided) // BLOCK
    c = np.asarray(collided[: n * BLOCK], dtype=float).reshape(n, BLOCK).mean(axis=1) * 1000
    p = np.asarray(progress[: n * BLOCK]).reshape(n, BLOCK).mean(axis=1)
    return c.tolist(), p.tolist()


def _pybullet(
    config: EnvConfig, spec: ArenaSpec, rule: Rule, steps: int, seed: int
) -> tuple[list[bool], list[float]]:
    env = EPuckEnv(arena=spec, config=config)
    rng = np.random.default_rng(seed)
    collided, progress = [], []
    try:
        env.reset(seed=seed)
        obs, _ = env.reset()
        for _ in range(steps):
            obs, _, terminated, truncated, info = env.step(rule(obs, rng))
            collided.append(bool(info["collision"]))
            progress.append(min(max(float(info["progress"]), -1.0), 1.0))
            if terminated or truncated:
                obs, _ = env.reset()
    finally:
        env.close()
    return collided, progress


def _batched(
    config: EnvConfig, spec: ArenaSpec, rule: Rule, steps: int, seed: int
) -> tuple[list[bool], list[float]]:
    world = BatchedWorld(config, [spec], [np.random.default_rng(seed)])
    rng = np.random.default_rng(seed)
    world.start(0)
    world.respawn(0)
    collided, progress = [], []
    obs = world.observations()[0]
    for _ in range(steps):
        r = world.step(np.array([rule(obs, rng)]))
        collided.append(bool(r.collision[0]))
        progress.append(min(max(float(r.progress[0]), -1.0), 1.0))
        if (r.collision[0] and world.respawn_on_collision) or r.stuck[0]:
            world.respawn(0)
        obs = world.observations()[0]
    return collided, progress


def compare_policies(
    config: EnvConfig, arena: str | ArenaSpec, steps: int, seed: int
) -> dict[str, Any]:
    """Each of :data:`POLICIES` for ``steps`` steps in both simulators.

    Returns
    -------
    dict
        Per policy: both simulators' collisions per 1,000 steps and progress, and the
        differences (batched minus pybullet) with Welch 95% intervals over blocks of
        :data:`BLOCK` steps.
    """
    if steps < 2 * BLOCK:
        raise ValueError(f"fixed policies need at least {2 * BLOCK} steps, got {steps}")
    spec = arena if isinstance(arena, ArenaSpec) else load_arena(arena)
    out: dict[str, Any] = {}
    for name, rule in POLICIES.items():
        cp, pp = _blocks(*_pybullet(config, spec, rule, steps, seed))
        cb, pb = _blocks(*_batched(config, spec, rule, steps, seed))
        dc, dp = welch(cb, cp), welch(pb, pp)
        out[name] = {
            "pybullet": {"collisions_per_1000": float(np.mean(cp)), "progress": float(np.mean(pp))},
            "batched": {"collisions_per_1000": float(np.mean(cb)), "progress": float(np.mean(pb))},
            "collisions_difference": [dc.mean, dc.half],
            "progress_difference": [dp.mean, dp.half],
        }
    return out
