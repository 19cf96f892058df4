"""Registering the Gymnasium environment ``dfrl/EPuck-v0``.

:func:`register_envs` is called by ``import dfrl`` and is also the package's
``gymnasium.envs`` entry point, which Gymnasium releases before 1.0 load at import (1.x
dropped plugin loading, so there ``import dfrl`` is what registers the id). It imports
neither pybullet nor the environment: the registry holds the entry point as text.
"""
from __future__ import annotations

ENV_ID = "dfrl/EPuck-v0"
"""Gymnasium id of the e-puck obstacle-avoidance environment."""


def register_envs() -> None:
    """Register :data:`ENV_ID` (``dfrl.robots.env:EPuckEnv``) once; later calls do nothing."""
    import gymnasium as gym

    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="dfrl.robots.env:EPuckEnv", max_episode_steps=1000)
