"""Robots that learn: a pybullet e-puck, its Gymnasium environment, tabular and
function-approximation learners (linear Q, DQN).

Importing the package registers the Gymnasium id ``dfrl/EPuck-v0``
(``gymnasium.make("dfrl/EPuck-v0", arena="r4")``). See ``robots/README.md``.

Public API for other layers: :class:`dfrl.robots.training.Trainer` / :class:`TrainerConfig`
(steppable training, live Q-table or parameter vector), :data:`dfrl.robots.learners.LEARNERS`,
:func:`dfrl.robots.tables.save_table` / :func:`dfrl.robots.tables.load_table`.
"""

from __future__ import annotations

from dfrl.robots.registration import ENV_ID, register_envs

register_envs()  # imports neither pybullet nor the environment (modules that use pybullet
# import it through dfrl.arenas.pybullet_quiet, without its banner)

__all__ = ["ENV_ID"]
