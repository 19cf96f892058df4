"""Robots that learn: a pybullet e-puck, its Gymnasium environment, tabular learners.

Importing the package registers the Gymnasium id ``dfrl/EPuck-v0``
(``gymnasium.make("dfrl/EPuck-v0", arena="r4")``). See ``robots/README.md``.

Public API for other layers: :class:`robots.training.Trainer` / :class:`TrainerConfig`
(steppable training, live Q-table), :data:`robots.learners.LEARNERS`,
:func:`robots.tables.save_table` / :func:`robots.tables.load_table`.
"""
from __future__ import annotations

import gymnasium as gym

from arenas.pybullet_quiet import load as _load_pybullet

_load_pybullet()

ENV_ID = "dfrl/EPuck-v0"

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="robots.env:EPuckEnv", max_episode_steps=1000)

__all__ = ["ENV_ID"]
