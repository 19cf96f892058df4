"""Registering the Gymnasium environment ``dfrl/EPuck-v0``.

:func:`register_envs` is called by ``import dfrl`` and is also the package's
``gymnasium.envs`` entry point, which Gymnasium releases before 1.0 load at import (1.x
dropped plugin loading, so there ``import dfrl`` is what registers the id). It imports
neither pybullet, numba nor the environments: the registry holds the entry points as text.
``gymnasium.make`` builds :class:`dfrl.robots.env.EPuckEnv` (pybullet);
``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")`` builds
:class:`dfrl.robots.vector_env.EPuckVectorEnv` (the batched simulator).
"""

from __future__ import annotations

ENV_ID = "dfrl/EPuck-v0"
"""Gymnasium id of the e-puck obstacle-avoidance environment."""


def register_envs() -> None:
    """Register :data:`ENV_ID` once (entry point ``dfrl.robots.env:EPuckEnv``, vector entry
    point ``dfrl.robots.vector_env:EPuckVectorEnv`` with Gymnasium 1.1 or later); later calls
    do nothing."""
    import gymnasium as gym

    if ENV_ID in gym.registry:
        return
    if hasattr(gym.vector, "AutoresetMode"):  # Gymnasium >= 1.1, whose VectorEnv it implements
        gym.register(
            id=ENV_ID,
            entry_point="dfrl.robots.env:EPuckEnv",
            max_episode_steps=1000,
            vector_entry_point="dfrl.robots.vector_env:EPuckVectorEnv",
        )
    else:
        gym.register(id=ENV_ID, entry_point="dfrl.robots.env:EPuckEnv", max_episode_steps=1000)
