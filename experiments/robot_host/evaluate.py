"""Greedy evaluations while a robot learns: ``eval_<robot>.csv`` and ``DFRL_EVAL`` lines.

Every ``eval_every`` iterations (:class:`dfrl.experiments.robot_host.config.RobotConfig`; never at
iteration 0) :class:`LiveEvaluator` measures the greedy policy of a copy of the robot's
current Q-table (a function learner: of its parameter vector) for ``eval_steps`` control steps with
:func:`dfrl.robots.evaluation.evaluate_policy`. The evaluation builds an environment of its
own (its own pybullet client, headless) and its own random generator seeded by
:func:`eval_seed`, so training is not disturbed: the trainer's generator, environment and
metrics are the same with and without evaluations (tested). Its cost is wall time only.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.robot_host.files import CsvLog
from dfrl.experiments.robot_host.lines import ProtocolLines

__all__ = ["EVAL_FIELDS", "LiveEvaluator", "eval_seed"]

#: Columns of ``eval_<robot>.csv`` (and of the results folder's ``live_evaluations.csv``).
EVAL_FIELDS: tuple[str, ...] = (
    "robot",
    "iteration",
    "arena",
    "steps",
    "collisions_per_1000",
    "distance",
    "progress",
    "coverage",
    "mean_reward",
)

#: Mixed into :func:`eval_seed` so that evaluation seeds never equal a training seed's stream.
_EVAL_SALT = 0xE7A1


def eval_seed(seed: int, iteration: int) -> int:
    """The seed of the evaluation of robot seed ``seed`` at ``iteration``: deterministic, a
    different one per iteration, in ``[0, 2**32)``.

    >>> eval_seed(1, 100) == eval_seed(1, 100) != eval_seed(1, 200)
    True
    """
    return int(np.random.SeedSequence([int(seed), int(iteration), _EVAL_SALT]).generate_state(1)[0])


class LiveEvaluator:
    """The evaluations of one run (see the module doc).

    Parameters
    ----------
    trainer_config : TrainerConfig
        The robot's (its simulation is made headless for the evaluations).
    robot : str
    seed : int
        The robot's training seed (see :func:`eval_seed`).
    every, steps : int
        ``eval_every`` (> 0) and ``eval_steps`` of the node config.
    out_dir : Path
        Where ``eval_<robot>.csv`` is written.
    lines : ProtocolLines
    upto : int or None
        Resuming from a checkpoint at this iteration: the file's rows up to it are kept.
    """

    def __init__(
        self,
        trainer_config: Any,
        robot: str,
        seed: int,
        every: int,
        steps: int,
        out_dir: Path,
        lines: ProtocolLines,
        upto: int | None = None,
    ) -> None:
        sim = dataclasses.replace(trainer_config.sim, connection="direct")
        self.config = trainer_config.replace(sim=sim)
        self.robot = robot
        self.seed = seed
        self.every = every
        self.steps = steps
        self.lines = lines
        self.path = Path(out_dir) / f"eval_{robot}.csv"
        keep = (lambda r: int(r["iteration"]) <= upto) if upto is not None else None
        self._log = CsvLog(self.path, EVAL_FIELDS, keep)

    def due(self, iteration: int) -> bool:
        """An evaluation is due after ``iteration``."""
        return iteration > 0 and iteration % self.every == 0

    def evaluate(
        self, iteration: int, q_table: np.ndarray | None = None, *, params: np.ndarray | None = None
    ) -> dict[str, Any]:
        """Measure the greedy policy of ``q_table`` (a function learner: of ``params``; copied
        first), append the row (flushed) and write the ``DFRL_EVAL`` line; return the row.

        Raises
        ------
        ValueError
            The table (vector) does not fit the configuration, or a measure is not finite.
        """
        from dfrl.robots.evaluation import PolicyKind, evaluate_policy

        if params is not None:
            r = evaluate_policy(
                self.config,
                PolicyKind.GREEDY,
                self.steps,
                eval_seed(self.seed, iteration),
                params=np.array(params),
            )
        else:
            r = evaluate_policy(
                self.config,
                PolicyKind.GREEDY,
                self.steps,
                eval_seed(self.seed, iteration),
                q_table=np.array(q_table),
            )
        row: dict[str, Any] = {
            "robot": self.robot,
            "iteration": iteration,
            "arena": str(self.config.arena),
            "steps": r.steps,
            "collisions_per_1000": r.collisions_per_1000,
            "distance": r.distance,
            "progress": r.progress,
            "coverage": r.coverage,
            "mean_reward": r.mean_reward,
        }
        bad = [k for k in EVAL_FIELDS[4:] if not math.isfinite(row[k])]
        if bad:
            raise ValueError(
                f"evaluation of {self.robot} at iteration {iteration}: not finite: {', '.join(bad)}"
            )
        self._log.row(
            tuple(repr(float(row[k])) if k in EVAL_FIELDS[4:] else row[k] for k in EVAL_FIELDS),
            flush=True,
        )
        self.lines.evaluation(iteration, r.collisions_per_1000, r.progress, r.coverage)
        return row

    def sync(self) -> None:
        """Flush and fsync the file (before a checkpoint)."""
        self._log.sync()

    def close(self) -> None:
        self._log.close()
