"""Evaluation of a fixed policy: collisions per 1,000 control steps, greedy vs random."""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from dfrl.robots.learners import greedy_action
from dfrl.robots.state import Discretiser
from dfrl.robots.training import TrainerConfig


class PolicyKind(str, Enum):
    """Policies that can be evaluated."""

    GREEDY = "greedy"  #: argmax of the Q-table (ties broken at random), no learning
    RANDOM = "random"  #: uniform random actions


@dataclass(frozen=True)
class EvalResult:
    """Outcome of :func:`evaluate_policy`.

    Attributes
    ----------
    policy : str
    steps : int
    collisions : int
    collisions_per_1000 : float
    distance : float
        Path length driven (m).
    mean_reward : float
    """

    policy: str
    steps: int
    collisions: int
    collisions_per_1000: float
    distance: float
    mean_reward: float


def evaluate_policy(
    config: TrainerConfig,
    policy: PolicyKind,
    steps: int,
    seed: int,
    q_table: np.ndarray | None = None,
) -> EvalResult:
    """Run a fixed policy in the configured arena and count collisions.

    Collisions and respawns follow the training rules (a collision respawns the robot at a
    random free pose; so does being stuck).

    Parameters
    ----------
    config : TrainerConfig
        Arena, simulation, actions, reward and discretisation (the learner is unused).
    policy : PolicyKind
    steps : int
        Control steps to run.
    seed : int
        Seeds the start/respawn poses and the random choices.
    q_table : np.ndarray, shape (n_states, n_actions), optional
        Required for GREEDY.
    """
    from dfrl.robots.env import EPuckEnv

    policy = PolicyKind(policy)
    disc = Discretiser(config.discretisation)
    rng = np.random.default_rng([seed, 7])
    env = EPuckEnv(arena=config.arena, config=config.env_config())
    try:
        n_actions = int(env.action_space.n)
        if policy is PolicyKind.GREEDY:
            if q_table is None:
                raise ValueError("a greedy evaluation needs a Q-table")
            if q_table.shape != (disc.n_states, n_actions):
                raise ValueError(f"Q-table shape {q_table.shape} does not fit the configuration "
                                 f"({disc.n_states}, {n_actions})")
        obs, info = env.reset(seed=seed, options={"random": True})
        # a random start so that evaluation seeds differ even in arenas with a fixed start
        obs, info = env.reset()
        collisions, distance, total = 0, 0.0, 0.0
        x, y, _ = info["pose"]
        for _ in range(steps):
            if policy is PolicyKind.GREEDY:
                action = greedy_action(q_table[disc(obs)], rng)
            else:
                action = int(rng.integers(n_actions))
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            collisions += bool(info["collision"])
            nx, ny, _ = info["pose"]
            distance += float(np.hypot(nx - x, ny - y))
            x, y = nx, ny
            if terminated or truncated:
                obs, info = env.reset()
                x, y, _ = info["pose"]
        return EvalResult(policy=policy.value, steps=steps, collisions=collisions,
                          collisions_per_1000=1000.0 * collisions / max(steps, 1),
                          distance=distance, mean_reward=total / max(steps, 1))
    finally:
        env.close()
