"""The e-puck's motion in one control step, measured in pybullet.

On a flat floor the robot's motion over one 64 ms step depends only on the command and on how
fast its wheels already turn, that is on the previous command (the velocity motors reach a new
speed within a few milliseconds, but not instantly: turning left after driving ahead turns
0.102 rad instead of 0.155, and moves 3 mm). :func:`measured_motion` drives the pybullet robot
through every pair (previous command, command), from rest too, and records the body-frame
displacement of the step; the batched simulator replays it. The table is measured once per
simulation and action set in a process (a few hundred milliseconds) and cached.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from dfrl.arenas.spec import ArenaSpec
from dfrl.robots.env import ActionSet
from dfrl.robots.world import SimConfig

#: Steps of the previous command before the measured one (the wheels' speed has settled).
SETTLE_STEPS: int = 3

_OPEN_FLOOR = ArenaSpec(name="open", size=(2.0, 2.0), wall_height=0.1,
                        description="an empty floor for measuring the robot's motion")


def body_delta(before: tuple[float, float, float],
               after: tuple[float, float, float]) -> tuple[float, float, float]:
    """``(forward, left, turn)``: the displacement from ``before`` to ``after`` in the frame
    of ``before`` (m, m) and the change of yaw (rad, in ``(-pi, pi]``)."""
    dx, dy = after[0] - before[0], after[1] - before[1]
    c, s = math.cos(before[2]), math.sin(before[2])
    return (c * dx + s * dy, -s * dx + c * dy, math.remainder(after[2] - before[2], 2 * math.pi))


@lru_cache(maxsize=8)
def measured_motion(sim: SimConfig, actions: ActionSet) -> np.ndarray:
    """Body-frame motion of one control step, shape (n_actions + 1, n_actions, 3).

    ``[0, a]`` is action ``a`` from rest, ``[p + 1, a]`` action ``a`` after ``SETTLE_STEPS``
    steps of action ``p``; the last axis is ``(forward, left, turn)`` (m, m, rad).
    """
    from dfrl.robots.env import EnvConfig, EPuckEnv

    actions = ActionSet(actions)
    n = len(actions.actions)
    out = np.zeros((n + 1, n, 3))
    env = EPuckEnv(arena=_OPEN_FLOOR, config=EnvConfig(sim=sim, actions=actions, stuck_steps=0))
    try:
        for prev in range(-1, n):
            for action in range(n):
                env.reset(seed=0, options={"pose": (0.0, 0.0, 0.0)})
                for _ in range(SETTLE_STEPS if prev >= 0 else 0):
                    env.step(prev)
                before = env.robot.pose()
                env.step(action)
                out[prev + 1, action] = body_delta(before, env.robot.pose())
    finally:
        env.close()
    return out
