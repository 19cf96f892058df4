"""A static robot: what a benchmark asks a robot process to serve instead of a learning robot.

A static robot has no simulation: it serves agents a random Q-table
(:class:`dfrl.pybridge.StaticTable`) or a random parameter vector with the layout of a function
learner's network (:class:`dfrl.pybridge.StaticParams`) until its process is told to stop.
``dfrl bench round`` asks for one through the robot process's config, since a robot process is
a separate OS process started from a JSON file: ``bench_table`` (``[STATES, ACTIONS]``) or
``bench_params`` (``{"samples": N}``) of :class:`~dfrl.experiments.robot_host.config.RobotConfig`.
This module is the one place those keys mean something: :func:`static_problems` checks them
(for :func:`~dfrl.experiments.robot_host.config.check_robot_config`) and :func:`static_robot`
builds what they ask for, the one seam :class:`~dfrl.experiments.robot_host.training.Training`
takes the robot it serves from.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dfrl.experiments.config_rules import known_algorithms

if TYPE_CHECKING:
    from dfrl.experiments.robot_host.config import RobotConfig
    from dfrl.pybridge.providers import ParamsProvider, TableProvider

__all__ = ["StaticRobot", "network_layout", "static_problems", "static_robot"]


@dataclass(frozen=True)
class StaticRobot:
    """What a static robot serves agents (built by :func:`static_robot`).

    Attributes
    ----------
    base : TableProvider or ParamsProvider
        The random table or parameter vector; only agents change it.
    shape : (int, int) or None
        The table's (n_states, n_actions); None for parameters (no table).
    """

    base: TableProvider | ParamsProvider
    shape: tuple[int, int] | None

    def save_held(self, out_dir: Path, robot: str, params: np.ndarray | None) -> None:
        """Write what the agents left a parameter robot as ``out_dir/params/<robot>.npy``
        (``params``: the vector it serves; None, a table robot's case: nothing is written)."""
        if self.shape is not None or params is None:
            return
        folder = out_dir / "params"
        folder.mkdir(parents=True, exist_ok=True)
        np.save(folder / f"{robot}.npy", params)


def static_robot(config: RobotConfig) -> StaticRobot | None:
    """The static robot ``config`` asks for (``bench_table`` or ``bench_params``), seeded by
    ``config.seed``; None when it asks for none (a learning robot)."""
    from dfrl.pybridge import StaticParams, StaticTable

    if config.bench_table is not None:
        shape = (int(config.bench_table[0]), int(config.bench_table[1]))
        return StaticRobot(StaticTable(shape, config.seed), shape)
    if config.bench_params is not None:  # a function learner's parameters, no table
        return StaticRobot(
            StaticParams(
                network_layout(config.trainer_config()),
                config.seed,
                int(config.bench_params["samples"]),
            ),
            None,
        )
    return None


def network_layout(config: Any) -> list[tuple[str, tuple[int, ...]]]:
    """The parameter layout a robot of the function learner ``config.algo`` offers agents.

    Built by the learner's own code (:func:`dfrl.robots.training.build_learner`) over the
    observation and actions of ``config``'s environment (the proximity sensors, the action
    set), without a simulation: what a static robot holds is what a real one offers.

    Parameters
    ----------
    config : dfrl.robots.training.TrainerConfig

    Raises
    ------
    ValueError
        ``config.algo`` is a tabular learner.
    """
    from dfrl.robots.learners import learner_kind
    from dfrl.robots.training import build_learner

    if learner_kind(config.algo) != "function":
        raise ValueError(f"{config.algo!r} is a tabular learner: it has no network")
    env = config.env_config()
    learner = build_learner(
        config,
        1,
        len(env.sim.robot.sensor_angles),
        len(env.actions.actions),
        np.random.default_rng(0),
    )
    return learner.param_layout


def static_problems(data: dict[str, Any]) -> list[str]:
    """The problems of ``bench_table`` and ``bench_params`` in a robot process config's JSON
    form (their types are checked with the other keys'): their forms, ``bench_params``'
    learner, and not both at once."""
    out = []
    table = data.get("bench_table")
    if isinstance(table, list) and (
        len(table) != 2
        or not all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in table)
    ):
        out.append(f"bench_table: expected [STATES, ACTIONS], two positive integers, got {table!r}")
    params = data.get("bench_params")
    if not isinstance(params, dict):
        return out
    samples = params.get("samples")
    if (
        set(params) != {"samples"}
        or isinstance(samples, bool)
        or not isinstance(samples, int)
        or samples < 0
    ):
        out.append(f'bench_params: expected {{"samples": N}}, N an integer >= 0, got {params!r}')
    if data.get("bench_table") is not None:
        out.append(
            "bench_params: a benchmark robot holds a bench table or bench params, "
            "not both (drop bench_table or bench_params)"
        )
    algo = data.get("algo", "qlearning")
    if isinstance(algo, str) and algo in known_algorithms():
        from dfrl.robots.learners import learner_kind

        if learner_kind(algo) != "function":
            out.append(
                f"bench_params: algo {algo!r} is a tabular learner, it has no network; "
                f"bench params need a function learner (linear, dqn)"
            )
    return out
