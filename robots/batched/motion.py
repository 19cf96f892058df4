"""The e-puck's motion in one control step, measured in pybullet.

On a flat floor the robot's motion over one 64 ms step depends mostly on the command and on
how fast its wheels already turn, that is on the previous command (the velocity motors reach a
new speed within a few milliseconds, but not instantly: turning left after driving ahead turns
0.102 rad instead of 0.155, and moves 3 mm). :func:`measured_motion` measures it in two parts:

* from rest: the pybullet robot placed at rest on an empty floor and given each command;
* after each command: the mean and standard deviation of the body-frame displacements of the
  steps with that (previous command, command) in a seeded random walk of ``WALK_STEPS`` steps
  (the previous command kept with probability one half, else a uniform one). The spread comes
  from what one previous command does not capture (how long it lasted, the contacts of the
  wheels and casters); the batched simulator draws it as Gaussian noise. (The motion after
  ``SETTLE_STEPS`` steps of the previous command, measured too, stands in for a pair the walk
  never took.)

Measured once per simulation and action set in a process (about a second) and cached.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from dfrl.arenas.spec import ArenaSpec
from dfrl.robots.env import ActionSet
from dfrl.robots.world import SimConfig

#: Steps of the previous command before the measured one (the wheels' speed has settled).
SETTLE_STEPS: int = 3
#: Steps of the random walk that measures the spread.
WALK_STEPS: int = 3000
#: Seed of the random walk.
WALK_SEED: int = 2026

_OPEN_FLOOR = ArenaSpec(
    name="open",
    size=(4.0, 4.0),
    wall_height=0.1,
    description="an empty floor for measuring the robot's motion",
)


@dataclass(frozen=True)
class Motion:
    """Body-frame motion of one control step, each of shape (n_actions + 1, n_actions, 3).

    ``[0, a]`` is action ``a`` from rest, ``[p + 1, a]`` action ``a`` after action ``p``; the
    last axis is ``(forward, left, turn)`` (m, m, rad).
    """

    mean: np.ndarray
    std: np.ndarray


def body_delta(
    before: tuple[float, float, float], after: tuple[float, float, float]
) -> tuple[float, float, float]:
    """``(forward, left, turn)``: the displacement from ``before`` to ``after`` in the frame
    of ``before`` (m, m) and the change of yaw (rad, in ``(-pi, pi]``)."""
    dx, dy = after[0] - before[0], after[1] - before[1]
    c, s = math.cos(before[2]), math.sin(before[2])
    return (c * dx + s * dy, -s * dx + c * dy, math.remainder(after[2] - before[2], 2 * math.pi))


def _settled(env, n: int) -> np.ndarray:  # noqa: ANN001 - EPuckEnv
    out = np.zeros((n + 1, n, 3))
    for prev in range(-1, n):
        for action in range(n):
            env.reset(seed=0, options={"pose": (0.0, 0.0, 0.0)})
            for _ in range(SETTLE_STEPS if prev >= 0 else 0):
                env.step(prev)
            before = env.robot.pose()
            env.step(action)
            out[prev + 1, action] = body_delta(before, env.robot.pose())
    return out


def _walk(env, n: int) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001 - EPuckEnv
    """Mean and standard deviation of each (previous command, command)'s step in the walk."""
    rng = np.random.default_rng(WALK_SEED)
    steps: list[list[list[tuple[float, float, float]]]] = [
        [[] for _ in range(n)] for _ in range(n + 1)
    ]
    env.reset(seed=0, options={"pose": (0.0, 0.0, 0.0)})
    prev = -1
    for _ in range(WALK_STEPS):
        keep = prev >= 0 and rng.random() < 0.5
        action = prev if keep else int(rng.integers(n))
        before = env.robot.pose()
        env.step(action)
        after = env.robot.pose()
        if max(abs(after[0]), abs(after[1])) > 1.5:  # far from the middle: start again
            env.reset(seed=0, options={"pose": (0.0, 0.0, float(rng.uniform(-3, 3)))})
            prev = -1
            continue
        steps[prev + 1][action].append(body_delta(before, after))
        prev = action
    mean = np.full((n + 1, n, 3), np.nan)
    std = np.zeros((n + 1, n, 3))
    for p in range(n + 1):
        for a in range(n):
            if len(steps[p][a]) >= 2:
                arr = np.asarray(steps[p][a])
                mean[p, a], std[p, a] = arr.mean(axis=0), arr.std(axis=0, ddof=1)
    return mean, std


@lru_cache(maxsize=8)
def measured_motion(sim: SimConfig, actions: ActionSet) -> Motion:
    """The motion of one control step for ``sim`` and ``actions`` (see the module doc)."""
    from dfrl.robots.env import EnvConfig, EPuckEnv

    actions = ActionSet(actions)
    n = len(actions.actions)
    env = EPuckEnv(arena=_OPEN_FLOOR, config=EnvConfig(sim=sim, actions=actions, stuck_steps=0))
    try:
        settled = _settled(env, n)
        walked, std = _walk(env, n)
    finally:
        env.close()
    # from rest: the settled measurement (the walk starts from rest once); elsewhere the walk's
    # mean, unless the walk never saw the pair
    mean = np.where(np.isnan(walked), settled, walked)
    mean[0] = settled[0]
    return Motion(mean=mean, std=std)
